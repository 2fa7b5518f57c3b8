"""What a robot model is and how one is made: the plain-number specification (:mod:`.spec`), the
strict model-file reader (:mod:`.fields`, :mod:`.reader`), D-H tables (:mod:`.dh`) and URDF files
(:mod:`.urdf`), cost models (:mod:`.cost`, :mod:`.cost_set`), processes, locks and joint errors."""
