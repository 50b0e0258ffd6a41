"""Hands: the spec (fingers, joints, preshapes) and the built-in hands (:mod:`.spec`), URDF text
and parsing (:mod:`.urdf`), and forward kinematics with the links' collision geometry
(:mod:`.kinematics`)."""
