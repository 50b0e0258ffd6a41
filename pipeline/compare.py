"""Two data trees compared file by file: the check that a change meant to keep behaviour (a
refactor, a speed-up) left every artefact byte-identical.

``python -m pipeline.compare REFERENCE CANDIDATE`` compares the ``.npz`` and ``.parquet`` files
under both folders (recordings, logs and timings hold wall-clock times and are left out) and
prints one line per file that differs or is missing on one side, then a count; it exits 1 when
any does. Keep a copy of ``data/`` from before the change as the reference, rerun, compare.
"""

import hashlib
from dataclasses import dataclass
from pathlib import Path

from .errors import PipelineError

#: the artefacts compared (every stage's outputs); other files carry times or ids of the run
PATTERNS = ("*.npz", "*.parquet")


@dataclass(frozen=True)
class TreeComparison:
    """Relative paths (sorted) of the compared files: ``same`` bytes, ``differ``ent bytes, and
    those only in the ``reference`` or only in the ``candidate`` tree."""

    same: tuple
    differ: tuple
    only_reference: tuple
    only_candidate: tuple

    @property
    def identical(self):
        return not (self.differ or self.only_reference or self.only_candidate)


def _files(root, patterns):
    root = Path(root)
    if not root.is_dir():
        raise PipelineError(f"{root}: not a folder")
    return {str(path.relative_to(root)) for pattern in patterns for path in root.rglob(pattern) if path.is_file()}


def _digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def compare_trees(reference, candidate, patterns=PATTERNS):
    """:class:`TreeComparison` of the files matching ``patterns`` under the folders ``reference``
    and ``candidate``, by their bytes."""
    ours, theirs = _files(reference, patterns), _files(candidate, patterns)
    both = sorted(ours & theirs)
    differ = tuple(path for path in both if _digest(Path(reference) / path) != _digest(Path(candidate) / path))
    return TreeComparison(
        same=tuple(path for path in both if path not in set(differ)),
        differ=differ,
        only_reference=tuple(sorted(ours - theirs)),
        only_candidate=tuple(sorted(theirs - ours)),
    )


def main(argv=None):
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m pipeline.compare", description=__doc__.split("\n\n")[0])
    parser.add_argument("reference", help="data tree from before the change")
    parser.add_argument("candidate", help="data tree from after it")
    args = parser.parse_args(argv)
    try:
        result = compare_trees(args.reference, args.candidate)
    except PipelineError as error:
        raise SystemExit(f"error: {error}") from None
    for label, paths in (
        ("differs", result.differ),
        ("only in reference", result.only_reference),
        ("only in candidate", result.only_candidate),
    ):
        for path in paths:
            print(f"{label}: {path}")
    counts = (len(result.same), len(result.differ), len(result.only_reference), len(result.only_candidate))
    print("%d identical, %d differ, %d only in reference, %d only in candidate" % counts)
    if not result.identical:
        sys.exit(1)


if __name__ == "__main__":
    main()
