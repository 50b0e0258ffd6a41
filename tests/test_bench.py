"""The stage bench's attribution of a profile to named parts (its timings are figures, not tests)."""

import cProfile
import pstats
import time

from pipeline.bench import STAGE_PARTS, _profile_parts


def read_inputs():
    time.sleep(0.05)


def work():
    read_inputs()  # nested: counted in its own part and in the caller's
    time.sleep(0.1)


def test_profile_parts_sum_the_cumulative_time_of_their_functions():
    profile = cProfile.Profile()
    profile.enable()
    work()
    read_inputs()
    profile.disable()
    parts = (
        ("read inputs", ((__file__, "read_inputs"),)),
        ("work", ((__file__, "work"),)),
        ("absent", ((__file__, "no_such_function"),)),
    )
    found = _profile_parts(pstats.Stats(profile), parts)
    assert list(found) == ["read inputs", "work", "absent"]
    assert 0.1 <= found["read inputs"] < 0.19  # both calls, the nested one included, not work's own sleep
    assert 0.15 <= found["work"] < 0.24
    assert found["absent"] == 0.0


def test_every_stage_part_names_a_function_of_this_tree():
    import importlib
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for stage, parts in STAGE_PARTS.items():
        importlib.import_module(f"stages.{stage}")
        for name, functions in parts:
            for suffix, function in functions:
                if suffix.startswith("<"):
                    continue
                text = (root / suffix).read_text()
                assert f"def {function}(" in text, f"{stage} part {name!r}: {suffix} has no {function}"
