"""Stage ``mat``: python -m stages.mat SURFACE.npz MEDIAL_AXIS.npz OUT.npz"""

import dataclasses

from pipeline.artefacts import MedialAxis, SurfaceSamples
from pipeline.cli import one_line_errors, params, stage_args, timed
from pipeline.mat import reconstruct


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "medial_axis", "out", argv=argv)
    with timed(args.timing, "mat"):
        spheres = reconstruct(SurfaceSamples.load(args.surface), MedialAxis.load(args.medial_axis),
                              **dataclasses.asdict(params().mat))
        spheres.save(args.out)
    print(f"mat {args.out}: {len(spheres)} medial spheres")


if __name__ == "__main__":
    main()
