"""Stage ``candidates``: python -m stages.candidates SYMMETRY.npz CONCAVITY.npz HAND OUT.parquet [--timing T.json]
[--log L.mcap]

HAND is a built-in hand name or a hand spec file (one entry of params.yaml ``candidates.hands``).
"""

from pipeline.artefacts import write_table
from pipeline.geometry.candidates import generate_for_hands
from pipeline.geometry.concavity import Concavities
from pipeline.geometry.symmetry import Symmetry
from pipeline.hands.spec import get_hand
from pipeline.stage_io import one_line_errors, params, stage_args, stage_run


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "symmetry", "concavities", "hand", "out", argv=argv)
    config = params()
    used = {
        "hand": args.hand,
        "approach_directions": config.candidates.approach_directions,
        "flipped_candidates": config.candidates.flipped_candidates,
        "centre_rims": config.candidates.centre_rims,
        "max_width_ratio": config.concavity.max_width_ratio,
    }
    inputs = [args.symmetry, args.concavities]
    with stage_run(args, "candidates", params=used, inputs=inputs, outputs=[args.out]) as run:
        table = generate_for_hands(
            Symmetry.load(args.symmetry),
            Concavities.load(args.concavities),
            [get_hand(args.hand)],
            approach_directions=used["approach_directions"],
            flipped_candidates=used["flipped_candidates"],
            centre_rims=used["centre_rims"],
            max_width_ratio=used["max_width_ratio"],
        )
        write_table(args.out, table)
        run.count(
            candidates=len(table),
            spheres=int(table.sphere_index.nunique()),
            **{f"on_{name}": int(count) for name, count in table.sphere_class.value_counts().items()},
        )
        if not len(table):
            run.warn(f"{args.out}: no candidate grasp for {args.hand} (no sphere of the reduced set fits the hand)")
    print(f"candidates {args.out}: {len(table)} for {args.hand}, on {table.sphere_index.nunique()} spheres")


if __name__ == "__main__":
    main()
