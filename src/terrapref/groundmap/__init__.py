"""The ground map: what the camera has shown of the ground around the vehicle, gathered over
frames, as named layers over one grid. The planner keeps the maps and hands them to the rules,
which read them and never keep their own.

- :mod:`.settings`: its size, resolution and voting, and the ground read from each image
  (:class:`~.settings.MapSettings`);
- :mod:`.layers`: the layers it holds over its grid (the class vote, when each cell was last
  voted on, the column each cell holds), one list where a new layer goes;
- :mod:`.map`: the map (:class:`~.map.GroundMap`): the votes of each frame, re-centring, reads;
  its compiled votes and reads: :mod:`.map_compiled`;
- :mod:`.attitude`: the camera's pitch and roll off its mount, from each frame's sky line, with
  which the map places the ground it sees (:mod:`.attitude_compiled`);
- :mod:`.columns`: how a class table's classes fall into the terrain columns the map counts;
- :mod:`.costmap`: the map's cells priced as a rule learned them, as other planners read them.
"""
