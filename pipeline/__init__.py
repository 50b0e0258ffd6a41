"""Grasp planning on the grid of medial spheres (Przybylski, Asfour, Dillmann 2011).

One module per concept; every function takes and returns numpy arrays or the
artefact dataclasses of :mod:`pipeline.artefacts`. Nothing here reads params files,
prints, or touches the global random state: the stages in ``stages/`` and the CLI in
:mod:`pipeline.__main__` do the I/O.
"""

__version__ = "0.1.0"
