"""The ``second_stage`` rule: C's best trajectories scored again with the second pieces beyond
them, by a linear utility fitted with C.

- :mod:`.lookahead`: the second pieces and their utilities U' (:mod:`.scores_compiled`);
- :mod:`.rule`: the rule itself: its configuration, what it reads of each frame for its fit
  (U', when it is fitted through the look-ahead), its file block and its decision;
  :func:`.rule.with_second_stage` adds, drops or reweighs it in a recipe's rules.
"""
