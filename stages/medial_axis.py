"""Stage ``medial_axis``: python -m stages.medial_axis SURFACE.npz OUT.npz"""

import dataclasses

from pipeline.artefacts import SurfaceSamples
from pipeline.cli import one_line_errors, params, stage_args, timed
from pipeline.medial_axis import medial_axis


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "out", argv=argv)
    with timed(args.timing, "medial_axis"):
        axis = medial_axis(SurfaceSamples.load(args.surface), **dataclasses.asdict(params().medial_axis))
        axis.save(args.out)
    print(f"medial_axis {args.out}: {len(axis.radii)} balls ({axis.method})")


if __name__ == "__main__":
    main()
