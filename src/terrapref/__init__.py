"""terrapref: learn how a person likes to drive off-road from a few minutes of demonstration.

The package is laid out as the data flows, in layers, bottom first; a layer imports only from
the layers below it (tests/test_layout.py checks this list against the code):

1. errors
2. extras (which optional extra a feature needs)
3. yamlio, fileio, progress, configargs, registry, records, sums, stops
4. tensorfile, terrain, grid
5. pngio, scenario (files)
6. world (terrain raster)
7. vehicle, plots (dynamics)
8. camera (sensing)
9. perception (what a robot's segmentation gets wrong)
10. sim (closed loop, Gymnasium env)
11. features (utility features U)
12. demos (driving and recording demonstrations)
13. dataset (featurising recordings into training sets, with what the rules read)
14. learning (C, the linear utility, model files)
15. groundmap (what the camera has shown of the ground, as layers over one grid; its costmap)
16. rules (decision rules, one package each: argmax, second stage, offset, speed)
17. planner (policies, the stop rule, route; it keeps the ground maps the rules read)
18. baselines, recipes
19. interop (robot logs, ONNX, MCAP, ROS)
20. evaluation, teleop
21. report, filekinds (which reader checks a file, templates)
22. cli, runtime, warm_up
"""

import os

# terrapref's numeric work is many small matrix products (a 21 x 64 network, 21 trajectories),
# for which BLAS threads cost far more than they save (docs/lab/2026-11-28-figures-from-code.md); results do not
# depend on it (learning/exact.py).
# The environment still decides where it says otherwise, and only before NumPy is loaded.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
