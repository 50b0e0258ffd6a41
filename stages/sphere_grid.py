"""Stage ``sphere_grid``: python -m stages.sphere_grid SPHERES.npz OUT.npz [--timing T.json] [--log L.mcap]"""

import dataclasses

from pipeline.artefacts import MedialSpheres
from pipeline.geometry import sphere_grid
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "spheres", "out", argv=argv)
    config = dataclasses.asdict(params().sphere_grid)
    with stage_run(args, "sphere_grid", params=config, inputs=[args.spheres], outputs=[args.out]) as run:
        grid = sphere_grid.build(MedialSpheres.load(args.spheres), **config)
        grid.save(args.out)
        run.count(spheres=len(grid), cells=int(grid.dims.prod()))
    print(f"sphere_grid {args.out}: {len(grid)} spheres in {int(grid.dims.prod())} cells")


if __name__ == "__main__":
    main()
