"""Stage ``classify``: python -m stages.classify SPHERE_GRID.npz OUT.npz"""

import dataclasses

import numpy as np

from pipeline.artefacts import SphereGrid
from pipeline.cli import one_line_errors, params, stage_args, timed
from pipeline.symmetry import CLASSES, classify


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "sphere_grid", "out", argv=argv)
    with timed(args.timing, "classify"):
        symmetry = classify(SphereGrid.load(args.sphere_grid), **dataclasses.asdict(params().classify))
        symmetry.save(args.out)
        counts = np.bincount(symmetry.class_id, minlength=len(CLASSES))
    print(f"classify {args.out}: {len(symmetry)} spheres, "
          + ", ".join(f"{name} {count}" for name, count in zip(CLASSES, counts)))


if __name__ == "__main__":
    main()
