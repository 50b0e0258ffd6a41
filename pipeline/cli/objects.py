"""``objects FOLDER``: params.yaml objects entries for every mesh of a folder."""

from pathlib import Path

from ..stage_io import PARAMS_FILE
from .options import only_stems, stderr, subcommand


def add(commands, prog):
    parser = subcommand(
        commands,
        "objects",
        help="params.yaml objects entries for every mesh in a folder",
        description="List every mesh under a folder (searched recursively) as params.yaml objects entries, after\n"
        "the checks of the sample stage (closed surface, units, finite coordinates...): a mesh that\n"
        "fails them is skipped with a warning. Nested files are named by their path, parts joined\n"
        "with '-'. --write replaces the objects section of a params file and keeps\n"
        "report.figure_objects naming objects of it.",
        examples=[
            f"{prog} objects meshes/ --scale 0.001 --write {PARAMS_FILE}   # then: dvc repro",
            f"{prog} objects benchmark/ --size 0.26 --only 1,41,81",
        ],
    )
    parser.add_argument("folder", help="folder of OBJ/STL/PLY/OFF/GLB meshes (searched recursively)")
    parser.add_argument("--scale", type=float, default=None, help="factor for every mesh (0.001 for mm; default: 1)")
    parser.add_argument(
        "--size", type=float, default=None, help="metres of each mesh's bounding-box diagonal, for unitless meshes"
    )
    parser.add_argument("--only", default=None, help="comma-separated file stems to keep (e.g. 1,41,81)")
    parser.add_argument("--prefix", default="", help="put before each object name")
    parser.add_argument(
        "--write",
        metavar="PARAMS",
        default=None,
        help="replace the objects section of this params file (else print the entries); "
        "its sample section and scales set the checks",
    )
    return parser


def run(args):
    from ..artefacts import atomic_write
    from ..geometry.catalogue import entry_lines, figure_objects_following, folder_entries, replace_objects

    params_path = args.write or (PARAMS_FILE if Path(PARAMS_FILE).is_file() else None)
    entries = folder_entries(
        args.folder,
        prefix=args.prefix,
        scale=args.scale,
        size=args.size,
        only=only_stems(args),
        params_path=params_path,
        warn=lambda message: stderr(f"warning: {message}"),
    )
    if not args.write:
        print("\n".join(["objects:"] + [f"  {line}" for line in entry_lines(entries)]))
        return
    text = replace_objects(Path(args.write).read_text(), entries)
    text, figures = figure_objects_following(text, list(entries), source=args.write)
    atomic_write(args.write, lambda stream: stream.write(text.encode()))
    print(f"wrote {len(entries)} objects into {args.write} (report.figure_objects: {', '.join(figures)})")
    from ..dag import ROOT, write_dvc_files

    if Path(args.write).resolve() == ROOT / "params.yaml":  # the DAG's own params: its objects' stage files
        changed = write_dvc_files()
        print(f"rewrote {len(changed)} stage files under {ROOT / 'dag'}: run `dvc repro`")
    else:
        print("with these objects in the project's params.yaml, run `python -m pipeline.dag`, then `dvc repro`")
