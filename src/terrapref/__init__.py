"""terrapref: learn how a person likes to drive off-road from a few minutes of demonstration.

The package is laid out as the data flows: ``scenario`` (files) -> ``world`` (terrain raster)
-> ``vehicle`` and ``camera`` (dynamics and sensing) -> ``sim`` (closed loop, Gymnasium env)
-> demonstrations -> features -> learning -> planner -> evaluation -> report.
"""

__version__ = "0.1.0"
