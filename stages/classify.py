"""Stage ``classify``: python -m stages.classify SPHERE_GRID.npz SURFACE.npz OUT.npz [--timing T.json]
[--log L.mcap] [--rrd R.rrd --recording-id ID]

The recording shows the object (SURFACE: mesh, samples, normals), every medial sphere and the
reduced set with each sphere's class, e1/e2 and neighbourhood centre of gravity (paper Fig. 2, 5).
"""

import dataclasses

import numpy as np

from pipeline.artefacts import SphereGrid, SurfaceSamples
from pipeline.geometry.symmetry import CLASSES, classify
from pipeline.outputs.recording import log_spheres, log_surface, log_symmetry, record_stage
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "sphere_grid", "surface", "out", argv=argv)
    config = params()
    used = dataclasses.asdict(config.classify)
    with stage_run(
        args, "classify", params=used, inputs=[args.sphere_grid, args.surface], outputs=[args.out], record=config.record
    ) as run:
        grid = SphereGrid.load(args.sphere_grid)
        symmetry = classify(grid, **used)
        symmetry.save(args.out)
        counts = dict(zip(CLASSES, np.bincount(symmetry.class_id, minlength=len(CLASSES)).tolist()))
        run.count(reduced_spheres=len(symmetry), **counts)
        if not len(symmetry):
            run.warn(f"{args.out}: empty reduced set (no sphere passes the object-angle and diameter filters)")

        def draw(stream, root):
            log_surface(stream, root, SurfaceSamples.load(args.surface), seed=config.seed)
            log_spheres(stream, root, grid)  # the grid holds every medial sphere of the mat stage
            log_symmetry(stream, root, symmetry)

        record_stage(run, draw)
    print(
        f"classify {args.out}: {len(symmetry)} spheres, "
        + ", ".join(f"{name} {count}" for name, count in counts.items())
    )


if __name__ == "__main__":
    main()
