"""Grasp planning on the grid of medial spheres (Przybylski, Asfour, Dillmann 2011).

The library, one concept per module, in sub-packages by what they are about:

- :mod:`pipeline.geometry`: meshes, surface samples, medial axis, spheres, sphere grid,
  symmetry classes, concavities, grasp candidates, mesh queries;
- :mod:`pipeline.hands`: hand specs, the built-in hands, URDF, kinematics;
- :mod:`pipeline.trial`: the kinematic grasp trial on the exact mesh and its quality;
- :mod:`pipeline.checks`: physics checks (pybullet, MuJoCo), robust force closure, ablation;
- :mod:`pipeline.outputs`: report, figures, recordings, export and evaluation of grasp files.

The modules left at this level are the plumbing: artefact types and their files
(:mod:`.artefacts`), params (:mod:`.params`), the random streams (:mod:`.seeds`), the DAG
(:mod:`.dag`), a stage's inputs and logs (:mod:`.stage_io`, :mod:`.logbook`), the in-process
chain and batch (:mod:`.plan`, :mod:`.batch`), ``dvc repro`` in lanes (:mod:`.repro`), worker
processes (:mod:`.pool`), the benchmarks (:mod:`.bench`), data-tree comparison
(:mod:`.compare`) and the command line (:mod:`pipeline.__main__`, one module per subcommand in
:mod:`pipeline.cli`). Functions take and return
numpy arrays or artefact dataclasses; randomness comes in as a seed or a generator. Files are
read and written by the stages in ``stages/``, the CLI and the plumbing.
"""

__version__ = "0.1.0"
