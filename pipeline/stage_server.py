"""Stage commands run in processes forked from a warm server (``make run``).

Every DVC stage is a fresh ``python -m stages.<name>`` process, and a trial or check stage spends
about 2 s of its 5-8 importing numpy, pandas, open3d, pybullet, MuJoCo and rerun before its
first line of work: 375 times a run. :mod:`pipeline.repro` starts one server that has imported
them (:func:`serve`) and names its socket in the environment (:data:`ADDRESS`); a stage command
that finds it there hands its arguments, working directory, environment, CPU set and standard
streams to the server (:func:`delegate`, called from ``stages/__init__.py``), which forks a
child that runs the stage module as ``__main__`` and sends back its exit status.

The child runs the same code on the same inputs as the command would: the server holds only
third-party libraries (it imports the ``pipeline`` modules to find theirs, then drops them, so
each child imports the project's code from disk and its log names the modules it used), and it
serves only commands with as many CPUs as its own, which it took before importing anything: a
library sizes its thread pool by them at load (OpenBLAS, OpenMP), as it would in the command's
own process. Without the variable, when no server answers or when it declines, the command
runs in its own process as before. The server runs nothing but imports, so its forks copy no
library thread mid-task.
"""

import gc
import json
import os
import signal
import socket
import struct
import sys

#: the environment variable holding the server's socket path
ADDRESS = "MEDIAL_GRASP_STAGE_SERVER"
#: imported by the server besides those of the ``pipeline`` modules: the libraries the stages
#: import inside functions
PRELOAD = (
    "numpy",
    "pandas",
    "pyarrow.parquet",
    "scipy.spatial",
    "open3d",
    "trimesh",
    "pybullet",
    "mujoco",
    "rerun",
    "tqdm",
    "numba",
)
_HEADER = struct.Struct("!I")
_DECLINED = "declined"


def preload():
    """Import :data:`PRELOAD` and every ``pipeline`` module a stage can run, then drop the
    project's own modules (``pipeline``, ``stages``) from ``sys.modules``, keeping the libraries
    they imported."""
    import importlib

    from .dag import REPORT, STAGES, code_deps

    names = set(PRELOAD)
    for entry in (*STAGES, REPORT):
        names |= {path[:-3].replace("/", ".").removesuffix(".__init__") for path in code_deps(entry.name)}
    for name in sorted(names):
        importlib.import_module(name)
    for name in [name for name in sys.modules if name.split(".")[0] in ("pipeline", "stages")]:
        del sys.modules[name]


def serve(address, cpus=None):
    """Listen on the UNIX socket ``address``, forking a child per request (see the module
    docstring), on the CPU set ``cpus`` (default: this process's); prints ``ready`` once it
    accepts them. Runs until killed."""
    if cpus:
        os.sched_setaffinity(0, cpus)
    preload()
    # the libraries' objects live as long as the server: out of the garbage collector's full
    # passes in every child (a simulate stage's took 0.15 s walking them)
    gc.freeze()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(address)
    server.listen(64)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # children are reaped by the kernel
    print("ready", flush=True)
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nobody reads it any more
    width = len(os.sched_getaffinity(0))
    while True:
        connection, _ = server.accept()
        if os.fork() == 0:
            server.close()
            _child(connection, width)  # never returns
        connection.close()


def _child(connection, width):
    """Run the request on ``connection`` in this (forked) process, unless it asks for another
    number of CPUs than ``width``; exits with its status."""
    status = 1
    try:
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)  # the stage may wait for processes of its own
        message, fds, _, _ = socket.recv_fds(connection, 1 << 16, 3)
        (length,) = _HEADER.unpack(message[: _HEADER.size])
        message = message[_HEADER.size :]
        while len(message) < length:
            message += connection.recv(length - len(message))
        request = json.loads(message)
        if len(request["cpus"]) != width:
            connection.sendall(f"{_DECLINED}\n".encode())
            os._exit(0)
        for target, fd in enumerate(fds):
            os.dup2(fd, target)
            os.close(fd)
        os.chdir(request["cwd"])
        os.environ.clear()
        os.environ.update(request["env"])
        os.sched_setaffinity(0, request["cpus"])
        connection.sendall(f"{os.getpid()}\n".encode())
        status = _run_module(request["module"], request["argv"])
    finally:
        _settle()
        try:
            connection.sendall(f"{status}\n".encode())
        finally:
            os._exit(status)


def run_stage(module, argv):
    """Run stage ``module`` as ``__main__`` with ``argv`` in this process, as ``python -m``
    would, and end the process with its exit status (:func:`_exit`): the command's own run,
    without a server (``stages/__init__.py``)."""
    _exit(_run_module(module, argv))


def _exit(status):
    """End this process with ``status`` once it has settled (:func:`_settle`), without the
    interpreter's teardown: a stage's outputs are written and closed by then, and freeing every
    module's objects one by one took 0.7-0.9 s of a 5 s ``simulate`` stage."""
    _settle()
    os._exit(status)


def _settle():
    """Wait for this process's threads other than daemons (a trial pool's closing, which removes
    the file its workers read) and flush its standard streams."""
    import threading

    for thread in threading.enumerate():
        if thread is not threading.main_thread() and not thread.daemon:
            thread.join()
    for stream in (sys.stdout, sys.stderr):
        stream.flush()


def _run_module(module, argv):
    """Run ``module`` as ``__main__`` with ``argv``, as ``python -m`` would; its exit status."""
    import runpy
    import traceback

    sys.argv = [module] + list(argv)
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as stop:
        if stop.code is None or isinstance(stop.code, int):
            return stop.code or 0
        print(stop.code, file=sys.stderr)
        return 1
    except BaseException:
        traceback.print_exc()
        return 1
    return 0


def delegate(module, argv):
    """Run stage ``module`` with ``argv`` in the server named by :data:`ADDRESS` and exit with its
    status; return (to run it here) when there is none, it does not answer or it declines."""
    address = os.environ.get(ADDRESS)
    if not address:
        return
    connection = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        connection.connect(address)
    except OSError:
        connection.close()
        return
    request = {
        "module": module,
        "argv": list(argv),
        "cwd": os.getcwd(),
        "env": dict(os.environ),
        "cpus": sorted(os.sched_getaffinity(0)),
    }
    payload = json.dumps(request).encode()
    message = _HEADER.pack(len(payload)) + payload
    reader = connection.makefile("r")
    try:
        sent = socket.send_fds(connection, [message], [0, 1, 2])
        connection.sendall(message[sent:])
        answer = reader.readline().strip()
    except OSError:
        answer = ""
    if answer in ("", _DECLINED):  # it runs here
        connection.close()
        return
    pid = int(answer)

    def forward(number, _frame):  # Ctrl-C or DVC stopping this command stops the stage
        os.kill(pid, number)

    for number in (signal.SIGINT, signal.SIGTERM):
        signal.signal(number, forward)
    line = reader.readline()
    raise SystemExit(int(line) if line.strip() else f"error: the stage server's process for {module} died")


def main(argv=None):
    import argparse

    parser = argparse.ArgumentParser(prog="python -m pipeline.stage_server", description=__doc__.split("\n\n")[0])
    parser.add_argument("address", help="the UNIX socket path to listen on")
    parser.add_argument("--cpus", help="the CPU set to serve on, comma-separated (default: this process's)")
    args = parser.parse_args(argv)
    serve(args.address, cpus=[int(cpu) for cpu in args.cpus.split(",")] if args.cpus else None)


if __name__ == "__main__":
    main()
