"""The kinematic grasp trial on the exact mesh, paper section IV: the engine (approach, close,
contacts; :mod:`.engine`), its distance queries (:mod:`.proximity`), contact regions
(:mod:`.contacts`), the epsilon quality (:mod:`.quality`, :mod:`.expanding_hull`), the
``simulate`` stage's protocol over worker processes (:mod:`.protocol`) and the pybullet
reference engine the tests hold the engine to (:mod:`.reference`)."""
