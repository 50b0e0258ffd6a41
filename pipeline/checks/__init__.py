"""Second opinions on a trial's grasp: the pybullet lift-and-shake and the convex parts it needs
(:mod:`.physics`), the same on MuJoCo (:mod:`.mujoco_check`), robust force closure
(:mod:`.robust`), the ``check`` stage's sample of trials and its table (:mod:`.protocol`), and
the ablation of the trial's modelling choices (:mod:`.ablate`)."""
