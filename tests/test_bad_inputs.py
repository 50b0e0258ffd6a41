"""Bad inputs and params: one clear line naming the file and the problem, no artefact."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from conftest import complete_params

REPO = Path(__file__).resolve().parents[1]


def run_sample(tmp_path, spec, extra=None, missing=()):
    params = complete_params({"objects": {"thing": spec}, "sample": {"count": 2000}, **(extra or {})})
    for section, key in missing:
        del (params[section] if key else params)[key or section]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    result = subprocess.run(
        [sys.executable, "-m", "stages.sample", "thing", "1.0", "out/surface.npz"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    return result, tmp_path / "out" / "surface.npz"


def write_obj(path, vertices, faces):
    lines = [f"v {x} {y} {z}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def box_obj(tmp_path, name="box.obj", extents=(0.1, 0.06, 0.02), drop_face=False):
    box = trimesh.creation.box(extents=extents)
    faces = box.faces[:-1] if drop_face else box.faces
    return write_obj(tmp_path / name, box.vertices, faces)


def nan_obj(tmp_path):
    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    vertices = box.vertices.copy()
    vertices[0, 0] = np.nan
    return write_obj(tmp_path / "nan.obj", vertices, box.faces)


def flat_obj(tmp_path):
    # two copies of a square, back to back: closed, but encloses nothing
    vertices = [[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0]]
    return write_obj(tmp_path / "flat.obj", vertices, [[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]])


def points_only(tmp_path):
    (tmp_path / "points.obj").write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nl 1 2\n")
    return str(tmp_path / "points.obj")


def empty_file(tmp_path):
    (tmp_path / "empty.stl").write_bytes(b"")
    return str(tmp_path / "empty.stl")


CASES = {
    "missing file": (lambda tmp: {"source": str(tmp / "nope.obj")}, "file not found"),
    "empty file": (lambda tmp: {"source": empty_file(tmp)}, "file is empty"),
    "NaN vertex": (lambda tmp: {"source": nan_obj(tmp)}, "NaN"),
    "zero volume": (lambda tmp: {"source": flat_obj(tmp)}, None),
    "millimetres": (lambda tmp: {"source": box_obj(tmp, extents=(100, 60, 20))}, "wrong units"),
    "no triangles": (lambda tmp: {"source": points_only(tmp)}, None),
    "unknown format": (lambda tmp: {"source": str(Path(box_obj(tmp)).rename(tmp / "box.xyz"))}, "unsupported format"),
    "unknown primitive": (lambda tmp: {"source": "primitive:banana"}, "unknown primitive"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_mesh_gives_one_line_and_no_artefact(case, tmp_path):
    make_spec, expected = CASES[case]
    result, out = run_sample(tmp_path, make_spec(tmp_path))
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    assert "Traceback" not in result.stderr
    if expected:
        assert expected in lines[0]
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_open_mesh_message_names_file_and_edges(tmp_path):
    # a box missing one triangle is repaired by hole filling; one missing a whole face
    # and a shared edge is not
    box = trimesh.creation.box(extents=(0.1, 0.06, 0.02))
    keep = np.abs(box.face_normals[:, 2] - 1) > 1e-9
    extra = np.vstack([box.vertices, [[0.0, 0.0, 0.05]]])
    faces = np.vstack([box.faces[keep], [[0, 1, 8]], [[1, 0, 8]], [[0, 8, 1]]])
    path = write_obj(tmp_path / "lidless.obj", extra, faces)
    result, out = run_sample(tmp_path, {"source": path})
    assert result.returncode == 2 and "lidless.obj" in result.stderr and "not closed" in result.stderr
    assert not out.exists()


def test_one_missing_triangle_is_repaired(tmp_path):
    result, out = run_sample(tmp_path, {"source": box_obj(tmp_path, drop_face=True)})
    assert result.returncode == 0, result.stderr
    assert out.exists()


def test_two_overlapping_bodies_are_united(tmp_path):
    from pipeline.artefacts import SurfaceSamples

    first = trimesh.creation.box(extents=(0.06, 0.02, 0.02))
    second = trimesh.creation.box(extents=(0.02, 0.06, 0.02))
    both = trimesh.util.concatenate([first, second])
    result, out = run_sample(tmp_path, {"source": write_obj(tmp_path / "cross.obj", both.vertices, both.faces)})
    assert result.returncode == 0, result.stderr
    mesh = trimesh.Trimesh(SurfaceSamples.load(out).vertices, SurfaceSamples.load(out).faces)
    # union volume of a plus sign: 2 * 0.06*0.02*0.02 - 0.02^3
    assert mesh.is_watertight and len(mesh.split()) == 1
    np.testing.assert_allclose(mesh.volume, 2 * 0.06 * 0.02 * 0.02 - 0.02**3, rtol=1e-6)


@pytest.mark.parametrize(
    "extra, expected",
    [
        ({"mat": {"tua": 0.1}}, "unknown key 'tua'"),
        ({"mat": {"tau": "big"}}, "mat.tau must be float"),
        ({"medial_axis": {"method": "cocone"}}, "medial_axis.method must be"),
        ({"seed": -1}, "seed must be a non-negative int"),
        ({"bogus": {}}, "unknown section 'bogus'"),
        ({"simulate": {"mu": -0.5}}, "simulate.mu must be >= 0"),
        ({"simulate": {"cone_edges": 2}}, "simulate.cone_edges must be >= 3"),
        ({"simulate": {"baseline_trials": -2}}, "simulate.baseline_trials must be -1, 0 or a count"),
        ({"candidates": {"hands": ["shadow"]}}, "candidates.hands must list built-in hands"),
        ({"report": {"figure_objects": ["mug"]}}, "report.figure_objects names 'mug', which is not under objects"),
        ({"missing": [("mat", "tau")]}, "mat: missing key 'tau'"),
        ({"missing": [("classify", None)]}, "missing section 'classify'"),
        ({"missing": [("seed", None)]}, "missing section 'seed'"),
    ],
)
def test_broken_params_give_one_line(extra, expected, tmp_path):
    extra = dict(extra)
    result, out = run_sample(
        tmp_path, {"source": "primitive:box", "extents": [0.1, 0.06, 0.02]}, extra, missing=extra.pop("missing", ())
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and expected in result.stderr and "params.yaml" in result.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "arguments, expected",
    [
        (["bench", "--only", "trials", "--trials", "0"], "bench: --trials must be >= 1, got 0"),
        (["bench", "--only", "trials", "--repeats", "0"], "bench: --repeats must be >= 1, got 0"),
        (["bench", "--only", "trials", "--reference-trials", "-3"], "bench: --reference-trials must be >= 0, got -3"),
        (["bench", "--only", "medial", "--sizes", "20000,-5"], "bench: --sizes must be positive sample counts"),
        (["bench", "--only", "medial", "--sizes", "many"], "bench: --sizes must be positive sample counts"),
        (
            ["plan", "primitive:box", "--workers", "-2", "--out", "out"],
            "--workers must be >= 0 (0: every core), got -2",
        ),
        (
            ["ablate", "primitive:box", "--hand", "parallel_jaw", "--workers", "-1", "--out", "out"],
            "--workers must be >= 0",
        ),
    ],
)
def test_bad_command_options_give_one_line_and_write_nothing(arguments, expected, tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", *arguments],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and expected in result.stderr, result.stderr
    assert list(tmp_path.iterdir()) == []


def test_point_cloud_with_and_without_normals(tmp_path):
    import open3d

    from pipeline.artefacts import SurfaceSamples

    rng = np.random.default_rng(2)
    direction = rng.standard_normal((3000, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    for name, normals in [("with.ply", direction), ("without.ply", None)]:
        cloud = open3d.geometry.PointCloud(open3d.utility.Vector3dVector(0.05 * direction))
        if normals is not None:
            cloud.normals = open3d.utility.Vector3dVector(normals)
        open3d.io.write_point_cloud(str(tmp_path / name), cloud)
        result, out = run_sample(tmp_path, {"source": str(tmp_path / name)})
        assert result.returncode == 0, result.stderr
        surface = SurfaceSamples.load(out)
        assert len(surface.points) == 3000 and (surface.face_index == -1).all()
        assert ((surface.normals * direction).sum(axis=1) > 0.95).all()
        out.unlink()


def open_tube(radius=0.02, height=0.1, sections=128, wave=0.0):
    """trimesh's cylinder without its two end caps; ``wave`` (m) bends the top rim out of its plane."""
    tube = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)
    vertices = tube.vertices.copy()
    top = vertices[:, 2] > 0
    vertices[top, 2] += wave * np.cos(3 * np.arctan2(vertices[top, 1], vertices[top, 0]))
    return trimesh.Trimesh(vertices, tube.faces[np.abs(tube.face_normals[:, 2]) < 0.5])


def test_planar_open_ends_are_capped():
    from pipeline.geometry.objects import RepairWarning, cap_planar_holes, validate_mesh

    tube = open_tube()
    before = tube.vertices.copy(), tube.faces.copy()
    assert len(tube.outline().entities) == 2
    with pytest.warns(RepairWarning, match=r"tube: open surface closed by capping its planar holes \(256 open edges\)"):
        mesh = validate_mesh(tube, name="tube", min_extent=0.005, max_extent=5.0)
    assert mesh.is_watertight and mesh.is_winding_consistent and len(mesh.split(only_watertight=False)) == 1
    # the capped tube is the cylinder: pi r^2 h, less 0.04 % for the 128-gon section
    np.testing.assert_allclose(mesh.volume, np.pi * 0.02**2 * 0.1, rtol=0.01)
    assert np.array_equal(tube.vertices, before[0]) and np.array_equal(tube.faces, before[1])
    assert cap_planar_holes(tube).volume == pytest.approx(mesh.volume)


def test_non_planar_open_end_is_rejected(tmp_path):
    # a rim waving +-4 mm on a 4 cm tube is 10 % of the loop out of plane: not capped
    tube = open_tube(wave=0.004)
    path = write_obj(tmp_path / "wavy.obj", tube.vertices, tube.faces)
    result, out = run_sample(tmp_path, {"source": path})
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1
    assert "wavy.obj" in lines[0] and "not closed (256 open edges" in lines[0]
    assert not out.exists()


def test_pybullet_mug_is_capped_and_united():
    # pybullet_data's objects/mug.obj: a watertight hollow cup and a handle tube whose two open
    # 12-gon ends (y = 0.0385 m) sit in the cup wall
    from pipeline.geometry.objects import RepairWarning, cap_planar_holes, load_source, validate_mesh

    _, raw = load_source("pybullet:objects/mug.obj")
    raw = trimesh.Trimesh(raw.vertices, raw.faces)
    cup, handle = sorted(raw.split(only_watertight=False), key=lambda body: -len(body.faces))
    assert cup.is_watertight and not handle.is_watertight
    handle = cap_planar_holes(handle)
    assert handle.is_watertight and handle.volume > 0
    with pytest.warns(RepairWarning, match=r"mug: open surface closed by capping its planar holes \(24 open edges\)"):
        mesh = validate_mesh(raw, name="mug", min_extent=0.005, max_extent=5.0)
    assert mesh.is_watertight and len(mesh.split(only_watertight=False)) == 1
    # the union holds the cup and nearly all the handle (its ends overlap the wall)
    assert cup.volume + 0.9 * handle.volume < mesh.volume <= cup.volume + handle.volume
    np.testing.assert_allclose(mesh.extents, [0.082, 0.122, 0.1], atol=0.001)
