"""The stage bench's attribution of a profile to named parts (its timings are figures, not tests)."""

import cProfile
import os
import pstats
import signal
import time

import numpy as np
import pytest
from numba import njit

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


def test_a_stage_command_runs_on_the_cpus_given_and_a_failed_one_raises_with_its_output(tmp_path):
    import sys

    from pipeline.bench import _stage_command

    cpu = min(os.sched_getaffinity(0))
    found = tmp_path / "cpus.txt"
    # the process as it starts: held to the CPU once started (a stage's threads start later)
    code = f"import os, time; time.sleep(0.2); open({str(found)!r}, 'w').write(str(sorted(os.sched_getaffinity(0))))"
    _stage_command([sys.executable, "-c", code], {cpu})
    assert found.read_text() == str([cpu])
    with pytest.raises(RuntimeError, match="(?s)failed:.*no such stage"):
        _stage_command([sys.executable, "-c", "import sys; print('no such stage'); sys.exit(3)"])


def test_occupancy_counts_the_seconds_at_each_number_of_running_stages():
    from pipeline.bench import occupancy

    # two lanes: a 0-10 s stage beside a 5-15 s one, then a gap, then one more stage
    assert occupancy([(0.0, 10.0), (5.0, 15.0), (17.0, 18.0)]) == {0: 2.0, 1: 11.0, 2: 5.0}
    assert occupancy([(3.0, 4.0)]) == {1: 1.0} and occupancy([]) == {}


def test_the_run_table_reads_each_stage_from_its_logs_start_and_end(tmp_path):
    from pipeline.bench import run_occupancy_bench
    from pipeline.logbook import mcap_log

    for name in ("sample", "mat"):  # one after the other: never two at once, a gap between
        with mcap_log(tmp_path / "duck" / f"{name}.mcap", name):
            time.sleep(0.05)
        time.sleep(0.05)
    row = run_occupancy_bench(logs=tmp_path, out=lambda line: None)
    assert row["stages"] == 2 and set(row["running_s"]) == {0, 1}
    assert row["running_s"][1] == pytest.approx(row["stage_s"]) and row["stage_s"] >= 0.1
    assert row["span_s"] == pytest.approx(row["stage_s"] + row["running_s"][0]) and row["running_s"][0] >= 0.05
    # one lane: the wait between its two stages is the gap with none running
    assert row["waits"]["count"] == 1 and row["waits"]["seconds"] == pytest.approx(row["running_s"][0])


def test_interleaved_rounds_keep_a_ratio_exact_while_the_machine_slows_down():
    from pipeline.bench import interleaved_seconds

    # a fake clock whose machine runs each round at a third of the last round's speed: a run of
    # `work` units costs work * slowdown seconds, and one core's run twice the all-cores' work
    now, slowdown, order = [0.0], [1.0], []

    def run(name, work):
        def action():
            order.append(name)
            now[0] += work * slowdown[0]
            if len(order) % 2 == 0:  # a round ends: the machine slows down
                slowdown[0] *= 3

        return action

    seconds = interleaved_seconds({"core": run("core", 2.0), "all": run("all", 1.0)}, 3, clock=lambda: now[0])
    assert order == ["core", "all"] * 3  # one of each per round, in turn
    assert seconds["core"].tolist() == [2.0, 6.0, 18.0]
    assert seconds["all"].tolist() == [1.0, 3.0, 9.0]
    assert (seconds["core"] / seconds["all"]).tolist() == [2.0, 2.0, 2.0]


def test_timeline_parts_split_a_two_process_call_into_its_steps():
    from pipeline.bench import timeline_parts

    timeline = [
        ("start workers", 0, 10.0, 10.1),
        ("set-up", 0, 10.1, 10.29),
        ("ship", 0, 10.29, 10.3),
        ("chunk", 0, 10.3, 11.0),
        ("chunk", 1, 10.32, 10.6),  # the worker's two chunks: 0.28 + 0.5 s
        ("results", 1, 10.6, 10.61),
        ("chunk", 1, 10.62, 11.12),
        ("results", 1, 11.12, 11.15),
        ("call", 0, 10.0, 11.17),
    ]
    parts = timeline_parts(timeline)
    expected = {
        "start": 0.1,
        "set-up": 0.19,
        "ship": 0.01,
        "caller": 0.7,
        "workers": 0.78,
        "lag": 0.02,
        "results": 0.04,
        "after": 0.02,
    }
    assert parts.keys() == expected.keys()
    assert all(abs(parts[name] - seconds) < 1e-9 for name, seconds in expected.items())
    # one process: no worker steps
    alone = timeline_parts(
        [("start workers", 0, 0.0, 0.0), ("set-up", 0, 0.0, 0.3), ("chunk", 0, 0.3, 1.0), ("call", 0, 0.0, 1.0)]
    )
    assert alone["ship"] == alone["workers"] == alone["lag"] == alone["results"] == alone["after"] == 0.0
    assert alone["caller"] == 0.7


def test_the_trial_bench_draws_its_sample_first_then_every_other_candidate_once():
    import pandas as pd

    from pipeline.bench import drawn_first

    candidates = pd.DataFrame({"id": range(100, 130)}, index=range(50, 80))
    ordered = drawn_first(candidates, 8)
    # the engine's sample first, as drawn before; then the 22 others, each once
    assert ordered.id[:8].tolist() == candidates.sample(8, random_state=0).id.tolist()
    assert sorted(ordered.id) == list(range(100, 130)) and ordered.index.tolist() == list(range(30))
    assert ordered.id.tolist() == drawn_first(candidates, 8).id.tolist()  # seeded
    assert drawn_first(candidates, 50).id.tolist() == candidates.sample(30, random_state=0).id.tolist()


def test_the_ratio_with_free_workers_shares_one_cores_trials_after_the_all_core_set_up():
    from pipeline.bench import free_workers_ratio

    # one core: 0.3 s of set-up and 0.6 s of trials; two cores: the set-up in 0.15 s, then
    # 0.3 s of trials each
    assert abs(free_workers_ratio({"set-up": 0.3, "caller": 0.6}, {"set-up": 0.15}, 2) - 0.9 / 0.45) < 1e-12
    # a set-up that no core shares bounds it below the core count
    assert abs(free_workers_ratio({"set-up": 0.3, "caller": 0.6}, {"set-up": 0.3}, 2) - 0.9 / 0.6) < 1e-12


def test_the_chunks_bench_runs_the_sample_whole_and_in_run_trials_own_chunks():
    from pipeline.bench import chunks_seconds
    from pipeline.trial.protocol import chunks

    class Engine:  # records the candidates of each run
        def __init__(self):
            self.runs = []

        def run(self, grasp, approach, orient, preshapes):
            self.runs.append((grasp[:, 0].astype(int).tolist(), list(preshapes)))

    count = 10
    grasp = np.arange(count, dtype=float)[:, None] * np.ones(3)
    targets = (grasp, grasp + 1, grasp + 2, [f"shape{row}" for row in range(count)])
    engine = Engine()
    seconds = chunks_seconds(engine, targets, 3, 2)
    assert list(seconds) == ["whole", 0, 1] and all(len(values) == 3 for values in seconds.values())
    dealt = [trials.tolist() for _, trials in chunks([0], [count], 2)]
    # each round: the whole sample, then each chunk, with the preshapes of its own rows
    assert engine.runs == [(rows, [f"shape{row}" for row in rows]) for rows in [list(range(count)), *dealt]] * 3
    assert sorted(dealt[0] + dealt[1]) == list(range(count))


def test_calls_run_at_once_each_in_a_forked_process_on_its_own_cpu(tmp_path):
    from pipeline.bench import at_once

    cpus = (sorted(os.sched_getaffinity(0)) * 2)[:2]

    def call(number):
        def run():  # marks its start, then waits for the other's: one run after the other would time out
            assert os.sched_getaffinity(0) == {cpus[number]} and os.getpid() != parent
            (tmp_path / f"started{number}").touch()
            waited = time.monotonic()
            while not (tmp_path / f"started{1 - number}").exists():
                assert time.monotonic() - waited < 30, "the other call never started"
                time.sleep(0.001)

        return run

    parent, before = os.getpid(), os.sched_getaffinity(0)
    seconds = at_once([call(0), call(1)], cpus)
    assert seconds.shape == (1, 2) and (seconds >= 0).all()
    assert os.sched_getaffinity(0) == before  # the parent keeps its CPUs


def test_each_run_at_once_starts_after_every_copy_ended_the_one_before(tmp_path):
    from pipeline.bench import at_once

    cpu = min(os.sched_getaffinity(0))

    def call(number):
        def run():  # a run's mark, written once the call has slept: a copy let go early would log before it
            time.sleep(0.2 if number else 0.0)
            with open(tmp_path / "log", "a") as file:
                file.write(f"{number} {os.getpid()}\n")

        return run

    seconds = at_once([call(0), call(1)], [cpu, cpu], 3)
    assert seconds.shape == (3, 2) and (seconds[:, 1] >= 0.2).all()
    runs = [line.split() for line in (tmp_path / "log").read_text().splitlines()]
    # copy 0 is fast and copy 1 slow, yet copy 0 starts each run only after copy 1's last
    assert [number for number, _ in runs] == ["0", "1"] * 3
    assert len({pid for _, pid in runs}) == 2  # each copy runs its call every time


def test_a_call_that_fails_at_once_raises_its_error_in_the_caller():
    from pipeline.bench import at_once

    def broken():
        raise ValueError("no trials")

    cpu = min(os.sched_getaffinity(0))
    with pytest.raises(RuntimeError, match="ValueError: no trials"):
        at_once([lambda: None, broken], [cpu, cpu])
    # a failure in a later run: the other copy, waiting to be let go, is not waited for forever
    runs = []

    def second_fails():  # each copy is a process of its own: the list counts that copy's runs
        runs.append(1)
        if len(runs) == 2:
            raise ValueError("second run")

    def hung(*_):
        raise TimeoutError("at_once waited for a copy that ended")

    before = signal.signal(signal.SIGALRM, hung)
    signal.alarm(60)
    try:
        with pytest.raises(RuntimeError, match="ValueError: second run"):
            at_once([lambda: None, second_fails], [cpu, cpu], 3)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, before)


def test_the_chunks_bench_runs_the_chunks_forked_alone_and_at_once(tmp_path):
    from pipeline.bench import chunks_seconds
    from pipeline.trial.protocol import chunks

    log = tmp_path / "runs"

    class Engine:  # appends each run's process, first candidate and count to a file the forks share
        def run(self, grasp, approach, orient, preshapes):
            with open(log, "a") as file:
                file.write(f"{os.getpid()} {int(grasp[0, 0])} {len(grasp)}\n")

    count = 10
    grasp = np.arange(count, dtype=float)[:, None] * np.ones(3)
    targets = (grasp, grasp + 1, grasp + 2, [None] * count)
    cpu = min(os.sched_getaffinity(0))
    seconds = chunks_seconds(Engine(), targets, 2, 2, [cpu])
    assert list(seconds) == ["whole", 0, 1, "forked", "at once"]
    assert seconds["forked"].shape == seconds["at once"].shape == (2, 2, 2)  # rounds, runs, chunks
    firsts = [int(trials[0]) for _, trials in chunks([0], [count], 2)]
    runs = [line.split() for line in log.read_text().splitlines()]
    # each round: the whole and the chunks here, then each chunk forked alone, twice in its copy,
    # then both forked at once, twice, then the whole here again, untimed (the pages the forks
    # shared written again before the next round's timed runs)
    here = str(os.getpid())
    assert [pid == here for pid, *_ in runs] == ([True] * 3 + [False] * 8 + [True]) * 2
    assert runs[11][1:] == runs[0][1:] == ["0", str(count)]  # the whole sample
    alone, together = runs[3:7], runs[7:11]
    assert [int(first) for _, first, _ in alone] == [firsts[0], firsts[0], firsts[1], firsts[1]]
    assert alone[0][0] == alone[1][0] != alone[2][0] == alone[3][0]  # a copy runs its chunk again
    # at once, each run of both copies before the next
    assert (
        sorted(int(first) for _, first, _ in together[:2])
        == sorted(int(first) for _, first, _ in together[2:])
        == firsts
    )
    assert len({pid for pid, *_ in runs[3:11]}) == 4  # a fresh copy for every chunk, each time


def test_the_together_factor_is_the_median_of_the_rounds_longest_together_over_alone():
    from pipeline.bench import together_factor

    forked = np.array([[1.0, 2.0], [1.0, 1.0], [0.5, 0.5]])
    together = np.array([[1.5, 2.2], [2.0, 1.0], [0.5, 0.6]])
    # rounds: 2.2 / 2.0, 2.0 / 1.0, 0.6 / 0.5
    assert abs(together_factor(forked, together) - 1.2) < 1e-12


def test_the_ratio_with_chunks_divides_one_cores_whole_by_the_longest_chunk_after_the_set_up():
    from pipeline.bench import chunked_ratio

    # 0.4 s set-up and 1.4 s of trials on one core; 0.25 s set-up and chunks of 0.75 and 0.8 s
    assert abs(chunked_ratio({"set-up": 0.4}, {"set-up": 0.25}, 1.4, [0.75, 0.8]) - 1.8 / 1.05) < 1e-12
    # chunks that cost no more than an even share of the whole: the set-ups alone bound it
    assert abs(chunked_ratio({"set-up": 0.3}, {"set-up": 0.15}, 0.6, [0.3, 0.3]) - 0.9 / 0.45) < 1e-12


def test_lane_gaps_give_each_stage_the_lane_that_freed_last_before_it():
    from pipeline.bench import lane_gaps

    # two lanes: a (0-10) and b (5-15) at once; c starts 0.5 s after a ended (b still runs);
    # d starts at 16, when both lanes are free: after b, which ended last (1 s before)
    spans = [(16.0, 18.0, "d"), (0.0, 10.0, "a"), (10.5, 12.0, "c"), (5.0, 15.0, "b")]
    assert lane_gaps(spans) == [(0.5, "a", "c"), (1.0, "b", "d")]
    assert lane_gaps([(0.0, 1.0, "a")]) == [] and lane_gaps([]) == []
    # both lanes free: a stage follows its own object's lane, though the other freed later
    spans = [(0.0, 1.0, "mug/sample"), (0.5, 2.0, "duck/sample"), (2.5, 3.0, "mug/mat")]
    assert lane_gaps(spans) == [(1.5, "mug/sample", "mug/mat")]


@njit(cache=False)
def _kernel_sum(count):
    total = 0.0
    for step in range(count):
        total += step * 0.5
    return total


def test_own_time_parts_put_numba_kernels_open3d_and_the_rest_apart():
    from pipeline.bench import own_time_parts

    class Stats:  # a pstats.Stats' table: (file, line, name) -> (calls, calls, own s, cumulative s, callers)
        stats = {
            (__file__, 1, "_kernel_sum"): (2, 2, 0.5, 0.5, {}),
            ("~", 0, "<built-in method open3d.pybind.t.geometry.compute_closest_points>"): (3, 3, 0.25, 0.25, {}),
            (__file__, 2, "read_inputs"): (1, 1, 0.125, 0.375, {}),  # a Python function of the same module
            ("~", 0, "<method 'reduce' of 'numpy.ufunc' objects>"): (9, 9, 0.0625, 0.0625, {}),
        }

    assert own_time_parts(Stats()) == {"kernels": 0.5, "open3d": 0.25, "calls": 0.1875}


def test_a_profiled_numba_kernel_counts_as_a_kernel_not_as_the_calls_around_it():
    from pipeline.bench import own_time_parts

    count = 20_000_000
    _kernel_sum(10)  # compiled before the profile
    profile = cProfile.Profile()
    profile.enable()
    assert _kernel_sum(count) == 0.5 * count * (count - 1) / 2
    profile.disable()
    parts = own_time_parts(pstats.Stats(profile))
    # the kernel's loop is the profile's time: the call around it is a few microseconds
    assert parts["kernels"] > 0 and parts["calls"] < parts["kernels"] and parts["open3d"] == 0.0
