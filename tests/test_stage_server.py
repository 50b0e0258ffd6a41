"""The warm stage server of ``make run`` (pipeline.stage_server): a stage command handed to it
runs in a forked child with the command's arguments, directory, environment, streams and exit
status, and writes the same bytes as in its own process; without a server, or with one that
declines, the command runs itself."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import complete_params
from pipeline import repro
from pipeline.logbook import read_log
from pipeline.stage_server import ADDRESS

REPO = Path(__file__).resolve().parents[1]

# stands in for a stage module: says who ran it, where and with what, then exits with status 3
PROBE = """
import os, sys
print("probe", os.getppid(), os.getcwd(), os.environ.get("PROBE_WORD"), sys.argv[1:], flush=True)
print("probe's stderr", file=sys.stderr)
sys.exit(3)
"""
# a command that hands module ``probe`` to the server, as stages/__init__.py does a stage
DELEGATE = "from pipeline.stage_server import delegate; delegate('probe', ['a b', '--c']); print('ran here')"


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working directory; module ``probe`` importable by the servers started from now on."""
    (tmp_path / "probe.py").write_text(PROBE)
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), str(REPO)]))
    monkeypatch.delenv(ADDRESS, raising=False)
    (tmp_path / "work").mkdir()
    return tmp_path / "work"


def run(command, cwd, address=None, **env):
    environment = {**os.environ, **env, **({ADDRESS: address} if address else {})}
    return subprocess.run(command, cwd=cwd, env=environment, capture_output=True, text=True)


# stands in for a stage module as its process ends: a thread that is not a daemon writes a file
# after a pause, and an object left to the interpreter's teardown would write another
SETTLING = """
import sys, threading, time
from pathlib import Path
out = Path(sys.argv[1])
def late():
    time.sleep(0.3)
    (out / "thread").write_text("done")
threading.Thread(target=late).start()
class Left:
    def __del__(self):
        (out / "teardown").write_text("ran")
left = Left()
print("settling", flush=True)
sys.exit(3)
"""


def test_a_stage_command_run_here_ends_with_its_threads_not_after_the_interpreters_teardown(work, tmp_path):
    # a stage package with this project's stages/__init__.py and the module above as a stage
    (tmp_path / "stages").mkdir()
    (tmp_path / "stages" / "__init__.py").write_text((REPO / "stages" / "__init__.py").read_text())
    (tmp_path / "stages" / "settling.py").write_text(SETTLING)
    for folder in ("here", "script"):
        (work / folder).mkdir()
    done = run([sys.executable, "-m", "stages.settling", str(work / "here")], work)
    assert (done.returncode, done.stdout) == (3, "settling\n")
    assert (work / "here" / "thread").read_text() == "done" and not (work / "here" / "teardown").exists()
    # the same module as a plain script: the teardown would have run
    plain = run([sys.executable, str(tmp_path / "stages" / "settling.py"), str(work / "script")], work)
    assert plain.returncode == 3 and (work / "script" / "teardown").read_text() == "ran"


def test_a_handed_command_runs_in_a_child_of_the_server_with_its_arguments_streams_and_status(work):
    with repro.warm_server() as ready:
        address = ready()
        assert address and os.path.exists(address)
        done = run([sys.executable, "-c", DELEGATE], work, address, PROBE_WORD="hello")
        probe, parent, cwd, word, argv = done.stdout.split(" ", 4)
        assert "pipeline.stage_server" in Path(f"/proc/{parent}/cmdline").read_text()
    assert done.returncode == 3 and "ran here" not in done.stdout
    assert (probe, cwd, word, argv.strip()) == ("probe", str(work), "hello", "['a b', '--c']")
    assert done.stderr == "probe's stderr\n"
    assert not os.path.exists(address)  # the server is gone with its socket


def test_without_a_server_the_command_runs_itself(work):
    done = run([sys.executable, "-c", DELEGATE], work, str(work / "no-such.sock"))
    assert (done.returncode, done.stdout) == (0, "ran here\n")


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPU sets of different sizes")
def test_a_server_declines_commands_with_another_number_of_cpus(work):
    # a library sizes its threads by the CPUs it finds at load: the server's must be the command's
    first = min(os.sched_getaffinity(0))
    with repro.warm_server({first}) as ready:
        address = ready()
        both = run([sys.executable, "-c", DELEGATE], work, address)
        one = run(["taskset", "-c", str(first), sys.executable, "-c", DELEGATE], work, address)
    assert (both.returncode, both.stdout) == (0, "ran here\n")
    assert one.returncode == 3 and one.stdout.startswith("probe")


def test_a_server_that_fails_to_start_leaves_the_stages_to_their_own_processes(work):
    with repro.warm_server({10**6}) as ready:  # no such CPU
        assert ready() is None


def test_a_stage_through_the_server_writes_the_same_bytes_and_errors(work):
    (work / "params.yaml").write_text(
        yaml.safe_dump(
            complete_params(
                {"objects": {"duck": {"source": "pybullet:duck.obj", "scale": 0.06}}, "sample": {"count": 2000}}
            )
        )
    )
    stage = [sys.executable, "-m", "stages.sample"]
    with repro.warm_server() as ready:
        address = ready()
        for folder, server in (("own", None), ("served", address)):
            done = run(stage + ["duck", "0.5", f"{folder}/surface.npz", "--log", f"{folder}/sample.mcap"], work, server)
            assert done.returncode == 0, done.stderr
        bad = [run(stage + ["nosuch", "1.0", "x.npz"], work, server) for server in (None, address)]
    assert (work / "own" / "surface.npz").read_bytes() == (work / "served" / "surface.npz").read_bytes()
    # the child imported the project's modules itself: its log names those the stage used
    modules = [dict(read_log(work / folder / "sample.mcap"))["/modules"] for folder in ("own", "served")]
    assert modules[0] == modules[1] and "pipeline.geometry.sampling" in modules[0]["modules"]
    assert [(done.returncode, done.stderr) for done in bad] == [
        (2, "error: params.yaml: no object named 'nosuch' under 'objects'\n")
    ] * 2
    assert not (work / "x.npz").exists()
