"""terrapref: learn how a person likes to drive off-road from a few minutes of demonstration.

The package is laid out as the data flows: ``scenario`` (files) -> ``world`` (terrain raster)
-> ``vehicle`` and ``camera`` (dynamics and sensing) -> ``sim`` (closed loop, Gymnasium env)
-> demonstrations -> features -> learning -> planner -> evaluation -> report.
"""

import os

# terrapref's numeric work is many small matrix products (a 21 x 64 network, 21 trajectories),
# for which BLAS threads cost far more than they save (training took 2.6 times as long with two
# threads as with one on a 2-core machine); results do not depend on it (learning/exact.py).
# The environment still decides where it says otherwise, and only before NumPy is loaded.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
