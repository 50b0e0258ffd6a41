"""Stage ``sphere_grid``: python -m stages.sphere_grid SPHERES.npz OUT.npz"""

import dataclasses

from pipeline import sphere_grid
from pipeline.artefacts import MedialSpheres
from pipeline.cli import one_line_errors, params, stage_args, timed


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "spheres", "out", argv=argv)
    with timed(args.timing, "sphere_grid"):
        grid = sphere_grid.build(MedialSpheres.load(args.spheres), **dataclasses.asdict(params().sphere_grid))
        grid.save(args.out)
    print(f"sphere_grid {args.out}: {len(grid)} spheres in {int(grid.dims.prod())} cells")


if __name__ == "__main__":
    main()
