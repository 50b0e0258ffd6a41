"""Stage ``medial_axis``: python -m stages.medial_axis SURFACE.npz OUT.npz [--timing T.json] [--log L.mcap]"""

import dataclasses

from pipeline.artefacts import SurfaceSamples
from pipeline.geometry.medial_axis import medial_axis
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "out", argv=argv)
    config = dataclasses.asdict(params().medial_axis)
    with stage_run(args, "medial_axis", params=config, inputs=[args.surface], outputs=[args.out]) as run:
        axis = medial_axis(SurfaceSamples.load(args.surface), **config)
        axis.save(args.out)
        run.count(balls=len(axis.radii))
    print(f"medial_axis {args.out}: {len(axis.radii)} balls ({axis.method})")


if __name__ == "__main__":
    main()
