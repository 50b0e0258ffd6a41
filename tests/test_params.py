"""Params: the repository's params.yaml is complete and agrees with the dataclass defaults, so
every entry point reads the same values; a missing or unknown key fails naming it."""

import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from pipeline.errors import BadParamsError
from pipeline.params import SECTIONS, Params, defaults, load_params

REPO = Path(__file__).resolve().parents[1]


def test_repository_params_equal_the_defaults():
    loaded, default = load_params(REPO / "params.yaml"), Params()
    # objects and scales say what the DVC run covers; every setting is the default
    for name in SECTIONS:
        assert getattr(loaded, name) == getattr(default, name), name
    assert (loaded.seed, loaded.record) == (default.seed, default.record)
    assert loaded.simulate.spheres_per_object == 200 and set(loaded.report.figure_objects) <= set(loaded.objects)


def test_printed_defaults_are_a_complete_file(tmp_path):
    printed = subprocess.run(
        [sys.executable, "-m", "pipeline.params"], capture_output=True, text=True, cwd=REPO, check=True
    ).stdout
    assert yaml.safe_load(printed) == defaults()
    (tmp_path / "params.yaml").write_text(printed)
    assert load_params(tmp_path / "params.yaml") == Params()


@pytest.mark.parametrize("section, key", [("simulate", "mu"), ("sample", "count"), ("report", "figure_objects")])
def test_a_missing_key_is_named(tmp_path, section, key):
    params = defaults()
    del params[section][key]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(BadParamsError, match=f"^{tmp_path / 'params.yaml'}: {section}: missing key '{key}'"):
        load_params(tmp_path / "params.yaml")
    assert key in {field.name for field in dataclasses.fields(SECTIONS[section])}


def test_an_unknown_key_is_named(tmp_path):
    params = defaults()
    params["simulate"]["spheres"] = 10
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(BadParamsError, match="simulate: unknown key 'spheres'"):
        load_params(tmp_path / "params.yaml")


def test_library_defaults_agree_with_the_params():
    import inspect

    from pipeline.geometry import sphere_grid
    from pipeline.geometry.candidates import generate, generate_for_hands
    from pipeline.geometry.mat import reconstruct
    from pipeline.geometry.medial_axis import medial_axis
    from pipeline.geometry.sampling import sample_object
    from pipeline.geometry.symmetry import classify
    from pipeline.params import (
        CandidatesParams,
        ClassifyParams,
        MatParams,
        MedialAxisParams,
        SampleParams,
        SphereGridParams,
    )

    checked = 0
    for function, section in (
        (sample_object, SampleParams),
        (medial_axis, MedialAxisParams),
        (reconstruct, MatParams),
        (sphere_grid.build, SphereGridParams),
        (classify, ClassifyParams),
        (generate, CandidatesParams),
        (generate_for_hands, CandidatesParams),
    ):
        default = section()
        for name, parameter in inspect.signature(function).parameters.items():
            if name in section.__dataclass_fields__ and parameter.default is not inspect.Parameter.empty:
                assert parameter.default == getattr(default, name), (function.__qualname__, name)
                checked += 1
    assert checked >= 20
