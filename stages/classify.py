"""Stage ``classify``: python -m stages.classify SPHERE_GRID.npz OUT.npz"""

import argparse
import dataclasses

import numpy as np

from pipeline.artefacts import SphereGrid
from pipeline.cli import one_line_errors, params
from pipeline.symmetry import CLASSES, classify


@one_line_errors
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("sphere_grid")
    parser.add_argument("out")
    args = parser.parse_args(argv)
    symmetry = classify(SphereGrid.load(args.sphere_grid), **dataclasses.asdict(params().classify))
    symmetry.save(args.out)
    counts = np.bincount(symmetry.class_id, minlength=len(CLASSES))
    print(f"classify {args.out}: {len(symmetry)} spheres, "
          + ", ".join(f"{name} {count}" for name, count in zip(CLASSES, counts)))


if __name__ == "__main__":
    main()
