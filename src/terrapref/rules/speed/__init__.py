"""The ``speed`` rule: how fast to drive the way the steering chose (:mod:`.rule`), learned from the drive (:mod:`.model`)."""
