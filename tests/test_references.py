"""Every ``pipeline.<module>[.<name>]`` and ``pipeline/<path>.py`` the code and the docs cite
exists, so that a moved or renamed module leaves no reader at a dead end."""

import importlib
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOTTED = re.compile(r"(?<![\w./])pipeline(?:\.\w+)+")
PATH = re.compile(r"(?<![\w./])pipeline/[\w/]+\.py")


def _texts():
    for pattern in ("pipeline/**/*.py", "stages/*.py", "docs/*.md", "README.md", "Makefile", "dag/*/dvc.yaml"):
        for path in sorted(ROOT.glob(pattern)):
            if path.name != Path(__file__).name:
                yield path, path.read_text()


def _resolves(dotted):
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            found = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for name in parts[cut:]:
            if not hasattr(found, name):
                return False
            found = getattr(found, name)
        return True
    return False


def test_cited_modules_and_names_exist():
    dead = set()
    for path, text in _texts():
        for dotted in set(DOTTED.findall(text)):
            if not _resolves(dotted.rstrip(".")):
                dead.add(f"{path.relative_to(ROOT)}: {dotted}")
        for cited in set(PATH.findall(text)):
            if not (ROOT / cited).is_file():
                dead.add(f"{path.relative_to(ROOT)}: {cited}")
    assert not dead, "\n".join(sorted(dead))
