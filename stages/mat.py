"""Stage ``mat``: python -m stages.mat SURFACE.npz MEDIAL_AXIS.npz OUT.npz [--timing T.json] [--log L.mcap]"""

import dataclasses

import numpy as np

from pipeline.artefacts import MedialAxis, SurfaceSamples
from pipeline.geometry.mat import reconstruct
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "medial_axis", "out", argv=argv)
    config = params()
    used = dataclasses.asdict(config.mat)
    with stage_run(args, "mat", params=used, inputs=[args.surface, args.medial_axis], outputs=[args.out]) as run:
        spheres = reconstruct(SurfaceSamples.load(args.surface), MedialAxis.load(args.medial_axis), **used)
        spheres.save(args.out)
        run.count(spheres=len(spheres), object_angle_ge_120deg=int((spheres.object_angle >= np.radians(120)).sum()))
    print(f"mat {args.out}: {len(spheres)} medial spheres")


if __name__ == "__main__":
    main()
