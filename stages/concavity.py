"""Stage ``concavity``: python -m stages.concavity SURFACE.npz OUT.npz [--timing T.json] [--log L.mcap]
[--rrd R.rrd --recording-id ID]

The recording shows the object, its concavities (counted ones in the ``encompassing`` colour)
and the filled object's spheres inside them.
"""

import dataclasses

from pipeline.artefacts import SurfaceSamples
from pipeline.errors import BadInputError
from pipeline.geometry.concavity import SECTIONS, encompass
from pipeline.outputs.recording import log_concavities, log_surface, record_stage
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "surface", "out", argv=argv)
    config = params()
    used = {
        **dataclasses.asdict(config.concavity),
        "seed": config.seed,
        **{name: dataclasses.asdict(getattr(config, name)) for name in SECTIONS},
    }
    with stage_run(
        args, "concavity", params=used, inputs=[args.surface], outputs=[args.out], record=config.record
    ) as run:
        surface = SurfaceSamples.load(args.surface)
        try:
            concavities = encompass(surface, **used)
        except BadInputError as err:
            raise BadInputError(f"{args.surface}: {err}") from None
        concavities.save(args.out)
        run.count(
            concavities=len(concavities.volume),
            counted=int(concavities.counted.sum()),
            encompassing_spheres=len(concavities),
        )

        def draw(stream, root):
            log_surface(stream, root, surface, seed=config.seed)
            log_concavities(stream, root, concavities)

        record_stage(run, draw)
    widths = ", ".join(f"{width * 100:.1f} cm" for width in concavities.width[concavities.counted])
    print(
        f"concavity {args.out}: {int(concavities.counted.sum())} of {len(concavities.volume)} concavities counted"
        + (f" (wide {widths})" if widths else "")
        + f", {len(concavities)} encompassing spheres"
    )


if __name__ == "__main__":
    main()
