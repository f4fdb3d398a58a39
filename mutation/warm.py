"""A warm pytest for mutation runs: one server imports the heavy libraries once, then forks a
fresh child per test run, which imports hopkinson (the mutated copy) and runs pytest.

cosmic-ray runs a command per mutant; a cold `python -m pytest` spends ~2 s of CPU importing
NumPy, SciPy, pymodbus and pytest's plugins before the first test, which on two shared cores
is most of a run. mutmut 3 forks like this itself, but it imports the code under test from a
mutants/ copy laid out by module name, which hopkinson's folder mapping (hopkinson.analysis =
analysis/) defeats; cosmic-ray edits the file in place and runs any command, so it only needs
this. Nothing of hopkinson is imported in the server: each child sees the file as it is now.

    python mutation/warm.py serve SOCKET           # started by mutation/run
    python mutation/warm.py run SOCKET TIMEOUT_S PYTEST_ARG...   # the target's test command
"""

from __future__ import annotations

import importlib
import json
import os
import signal
import socket
import sys
import time

PRELOAD = ("numpy", "scipy", "scipy.signal", "scipy.optimize", "scipy.linalg", "scipy.stats",
           "scipy.interpolate", "scipy.fft", "h5py", "pymodbus", "pymodbus.client", "pymodbus.server",
           "pyvisa", "serial", "sqlalchemy", "tomli_w", "platformdirs", "pytest", "_pytest.python",
           "xdist", "pytest_timeout", "pytestqt.plugin", "PySide6.QtCore")


def serve(path: str) -> None:
    sys.dont_write_bytecode = True  # a mutant's module must be compiled from its source each time
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - an absent library is imported by the child if needed
            pass
    if os.path.exists(path):
        os.unlink(path)
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(path)
    server.listen(1)
    while True:
        conn, _ = server.accept()
        with conn:
            request = json.loads(conn.makefile().readline())
            if request.get("stop"):
                return
            conn.sendall(f"{_run(request)}\n".encode())


def _run(request: dict) -> int:
    """Fork, run pytest in the child with the request's arguments; its exit code (1 on timeout)."""
    pid = os.fork()
    if pid == 0:
        os.setsid()
        os.chdir(request["cwd"])
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        import pytest

        code = 1
        try:
            code = int(pytest.main(request["args"]))
        finally:
            os._exit(code)
    deadline = time.monotonic() + float(request["timeout_s"])
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status)
        time.sleep(0.05)
    os.killpg(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return 1


def run(path: str, timeout_s: str, args: list[str]) -> int:
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    client.connect(path)
    client.sendall((json.dumps({"cwd": os.getcwd(), "args": args, "timeout_s": timeout_s}) + "\n").encode())
    return int(client.makefile().readline() or 1)


def stop(path: str) -> None:
    client = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    client.connect(path)
    client.sendall(b'{"stop": true}\n')


if __name__ == "__main__":
    command, path, *rest = sys.argv[1:]
    if command == "serve":
        serve(path)
    elif command == "stop":
        stop(path)
    else:
        sys.exit(run(path, rest[0], rest[1:]))
