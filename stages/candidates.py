"""Stage ``candidates``: python -m stages.candidates SYMMETRY.npz OUT.parquet"""


from pipeline.artefacts import write_table
from pipeline.candidates import generate_for_hands
from pipeline.cli import one_line_errors, params, stage_args
from pipeline.hands import get_hand
from pipeline.symmetry import Symmetry


@one_line_errors
def main(argv=None):
    args = stage_args(__doc__, "symmetry", "out", argv=argv)
    config = params().candidates
    table = generate_for_hands(Symmetry.load(args.symmetry), [get_hand(name) for name in config.hands],
                               approach_directions=config.approach_directions,
                               flipped_candidates=config.flipped_candidates)
    write_table(args.out, table)
    print(f"candidates {args.out}: " + ", ".join(f"{hand} {count}" for hand, count
                                                 in table.groupby("hand").size().items()))


if __name__ == "__main__":
    main()
