"""Artefacts: round trip, atomic writes, clear errors on bad files."""

import numpy as np
import pytest

from pipeline.artefacts import MedialAxis, MedialSpheres, atomic_write
from pipeline.errors import ArtefactError


def spheres():
    return MedialSpheres(
        centers=np.zeros((2, 3)),
        radii=np.array([1.0, 2.0]),
        contacts=np.array([[0, 1], [1, -1]]),
        object_angle=np.array([3.0, 0.0]),
        key="abc",
    )


def test_round_trip(tmp_path):
    spheres().save(tmp_path / "s.npz")
    loaded = MedialSpheres.load(tmp_path / "s.npz")
    assert loaded.key == "abc" and np.array_equal(loaded.contacts, [[0, 1], [1, -1]])
    assert list(tmp_path.iterdir()) == [tmp_path / "s.npz"]


def test_failed_write_leaves_nothing(tmp_path):
    def explode(stream):
        stream.write(b"partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(tmp_path / "out.npz", explode)
    assert list(tmp_path.iterdir()) == []


def test_bad_files_give_one_line_errors(tmp_path):
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ArtefactError, match="junk.npz: not a readable"):
        MedialSpheres.load(tmp_path / "junk.npz")
    with pytest.raises(ArtefactError, match="missing"):
        MedialSpheres.load(tmp_path / "absent.npz")
    spheres().save(tmp_path / "s.npz")
    with pytest.raises(ArtefactError, match="is not a medial_axis artefact"):
        MedialAxis.load(tmp_path / "s.npz")


def test_shape_is_checked():
    with pytest.raises(ArtefactError, match="centers"):
        MedialSpheres(
            centers=np.zeros((2, 2)), radii=np.ones(2), contacts=np.zeros((2, 1)), object_angle=np.ones(2), key="k"
        )
