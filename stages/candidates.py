"""Stage ``candidates``: python -m stages.candidates SYMMETRY.npz HAND OUT.parquet [--timing T.json]

HAND is a built-in hand name or a hand spec file (one entry of params.yaml ``candidates.hands``).
"""

from pipeline.artefacts import write_table
from pipeline.candidates import generate_for_hands
from pipeline.cli import one_line_errors, params, stage_args, timed
from pipeline.hands import get_hand
from pipeline.symmetry import Symmetry


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "symmetry", "hand", "out", argv=argv)
    config = params().candidates
    with timed(args.timing, "candidates"):
        table = generate_for_hands(Symmetry.load(args.symmetry), [get_hand(args.hand)],
                                   approach_directions=config.approach_directions,
                                   flipped_candidates=config.flipped_candidates)
        write_table(args.out, table)
    print(f"candidates {args.out}: {len(table)} for {args.hand}, "
          f"on {table.sphere_index.nunique()} spheres")


if __name__ == "__main__":
    main()
