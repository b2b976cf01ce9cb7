"""terrapref: learn how a person likes to drive off-road from a few minutes of demonstration.

The package is laid out as the data flows, in layers, bottom first; a layer imports only from
the layers below it (tests/test_layout.py checks this list against the code):

1. errors
2. yamlio, fileio, progress, configargs, grid, registry
3. tensorfile, terrain
4. pngio, scenario (files)
5. world (terrain raster)
6. vehicle, plots (dynamics)
7. camera (sensing)
8. perception (what a robot's segmentation gets wrong)
9. sim (closed loop, Gymnasium env)
10. features (utility features U, look-ahead, corridor)
11. demos (recordings, datasets)
12. learning (C, linear and corridor fits, model files)
13. planner (policies, decision stages, costmap, route)
14. baselines, recipes
15. interop (robot logs, ONNX, MCAP, ROS)
16. evaluation, teleop
17. report
18. cli, runtime, warm_up
"""

import os

# terrapref's numeric work is many small matrix products (a 21 x 64 network, 21 trajectories),
# for which BLAS threads cost far more than they save (training took 2.6 times as long with two
# threads as with one on a 2-core machine); results do not depend on it (learning/exact.py).
# The environment still decides where it says otherwise, and only before NumPy is loaded.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
