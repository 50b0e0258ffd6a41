"""Stage ``sample``: python -m stages.sample OBJECT SCALE OUT.npz [--timing T.json] [--log L.mcap]

OBJECT names an entry of params.yaml ``objects``; SCALE (one of ``scales``) multiplies its size.
"""

import dataclasses


from pipeline import seeds
from pipeline.errors import BadParamsError
from pipeline.geometry.objects import parse_spec, source_key
from pipeline.geometry.sampling import sample_object
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "object", "scale", "out", argv=argv)
    config = params()
    if args.object not in config.objects:
        raise BadParamsError(f"params.yaml: no object named {args.object!r} under 'objects'")
    used = {
        "seed": config.seed,
        "object": args.object,
        "spec": config.objects[args.object],
        "scale": float(args.scale),
        **dataclasses.asdict(config.sample),
    }
    with stage_run(args, "sample", params=used, outputs=[args.out]) as run:
        source, scale, shape = parse_spec(args.object, config.objects[args.object])
        surface = sample_object(
            source,
            scale=scale * float(args.scale),
            shape=shape,
            rng=seeds.surface_samples(config.seed),
            source_key=source_key(source, shape),
            **dataclasses.asdict(config.sample),
        )
        surface.save(args.out)
        run.count(
            samples=len(surface.points),
            spacing_m=surface.spacing,
            mesh_vertices=len(surface.vertices),
            mesh_faces=len(surface.faces),
        )
    print(f"sample {args.object} x{args.scale}: {len(surface.points)} samples, spacing {surface.spacing * 1e3:.3f} mm")


if __name__ == "__main__":
    main()
