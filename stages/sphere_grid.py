"""Stage ``sphere_grid``: python -m stages.sphere_grid SPHERES.npz OUT.npz"""

import argparse
import dataclasses

from pipeline import sphere_grid
from pipeline.artefacts import MedialSpheres
from pipeline.cli import one_line_errors, params


@one_line_errors
def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("spheres")
    parser.add_argument("out")
    args = parser.parse_args(argv)
    grid = sphere_grid.build(MedialSpheres.load(args.spheres), **dataclasses.asdict(params().sphere_grid))
    grid.save(args.out)
    print(f"sphere_grid {args.out}: {len(grid)} spheres in {int(grid.dims.prod())} cells")


if __name__ == "__main__":
    main()
