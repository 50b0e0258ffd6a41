"""``hands``: render the built-in hands, or export one as URDF + spec."""

from .options import subcommand


def add(commands, prog):
    from ..hands.spec import HANDS

    parser = subcommand(
        commands,
        "hands",
        help="render the built-in hands, or export one as URDF + spec",
        description=f"Render the built-in hands, or export one as URDF + spec file.\n"
        f"built-in hands: {', '.join(HANDS)}",
        examples=[
            f"{prog} hands --render pictures",
            f"{prog} hands --export parallel_jaw myhand   # then: plan ... --hand myhand/parallel_jaw.yaml",
        ],
    )
    parser.add_argument("--render", metavar="DIR", help="write DIR/<hand>.png, open and closed on an object")
    parser.add_argument(
        "--export",
        nargs=2,
        metavar=("HAND", "DIR"),
        help="write DIR/HAND.urdf and DIR/HAND.yaml (a spec --hand accepts)",
    )
    parser.set_defaults(parser=parser)
    return parser


def run(args):
    if not (args.render or args.export):
        args.parser.error("give --render DIR and/or --export HAND DIR")
    if args.export:
        from ..hands.spec import export_hand, get_hand

        print(f"wrote {export_hand(get_hand(args.export[0]), args.export[1])}")
    if args.render:
        from ..outputs.render import render_builtin_hands

        for path in render_builtin_hands(args.render):
            print(f"wrote {path}")
