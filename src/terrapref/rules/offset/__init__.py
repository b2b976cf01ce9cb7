"""The ``offset`` rule (the default planner's): hold a lateral offset from the path that a
utility learned from the driver prices best, and steer to it.

- :mod:`.geometry`: the candidate offsets, the stations read along the path, the footprint and
  the settings of the ground map it reads (:class:`~.geometry.OffsetGeometry`; the map itself is
  terrapref.groundmap's, kept by the planner);
- :mod:`.features`: what driving at each offset would cross (:mod:`.offsets_compiled`);
- :mod:`.steering`: pure pursuit toward an offset, and its inverse, the offset a driver's
  command was steering for (the training labels);
- :mod:`.fit`: the utility fitted to those labels;
- :mod:`.rule`: the rule itself: its configuration, what it reads of each frame for its fit,
  its file block, and its decision (with the ways to offsets checked against lethal terrain:
  :mod:`.reach_compiled`).
"""
