"""The data-tree comparison (pipeline.compare) that shows a refactor kept every artefact's bytes."""

import numpy as np
import pytest

from pipeline.compare import compare_trees, main
from pipeline.errors import PipelineError


def _tree(root, arrays):
    for relative, values in arrays.items():
        path = root / relative
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, values=values)
    (root / "duck" / "timing.json").write_text(str(root))  # differs, but is not an artefact
    return root


def test_identical_trees_and_each_kind_of_difference(tmp_path, capsys):
    arrays = {"duck/1.0/surface.npz": np.arange(5.0), "duck/0.5/surface.npz": np.ones(3)}
    reference = _tree(tmp_path / "a", arrays)
    same = _tree(tmp_path / "b", arrays)
    assert compare_trees(reference, same).identical
    assert compare_trees(reference, same).same == ("duck/0.5/surface.npz", "duck/1.0/surface.npz")
    main([str(reference), str(same)])
    assert "2 identical, 0 differ" in capsys.readouterr().out

    changed = {"duck/1.0/surface.npz": np.arange(5.0) + 1e-15, "duck/1.0/extra.npz": np.zeros(1)}
    other = _tree(tmp_path / "c", changed)
    result = compare_trees(reference, other)
    assert not result.identical
    assert result.differ == ("duck/1.0/surface.npz",)
    assert result.only_reference == ("duck/0.5/surface.npz",)
    assert result.only_candidate == ("duck/1.0/extra.npz",)
    with pytest.raises(SystemExit) as stop:
        main([str(reference), str(other)])
    assert stop.value.code == 1
    assert "differs: duck/1.0/surface.npz" in capsys.readouterr().out


def test_a_missing_folder_is_named():
    with pytest.raises(PipelineError, match="nowhere: not a folder"):
        compare_trees("nowhere", ".")
