"""Stage ``decompose``: python -m stages.decompose SURFACE.npz SCALE PARTS.npz [--timing T.json] [--log L.mcap]

The object's convex parts (pybullet's V-HACD), the dynamic body of the physics check, from its
surface at SCALE (the first of ``scales``); the check of each scale scales them to its own.
None (no V-HACD) when ``checks.physics`` is false.
"""

from pipeline.artefacts import SurfaceSamples
from pipeline.checks.physics import decompose
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "scale", "parts", argv=argv)
    checks = params().checks
    used = {"vhacd_resolution": checks.vhacd_resolution, "physics": checks.physics, "scale": float(args.scale)}
    with stage_run(args, "decompose", params=used, inputs=[args.surface], outputs=[args.parts]) as run:
        parts = decompose(SurfaceSamples.load(args.surface), **used)
        parts.save(args.parts)
        run.count(parts=len(parts.part_start) - 1, vertices=len(parts.vertices))
    print(f"decompose {args.parts}: {len(parts.part_start) - 1} convex parts")


if __name__ == "__main__":
    main()
