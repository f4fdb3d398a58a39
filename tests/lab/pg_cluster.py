"""A throw-away PostgreSQL cluster in a temporary folder, for the tests and benchmarks/bench_lab.py:
initdb and pg_ctl as the `postgres` user when run as root (the server refuses root), listening
on 127.0.0.1 only at a free port, its unix socket in that folder; stopped and removed after."""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import socket
import subprocess
import tempfile
from collections.abc import Iterator
from pathlib import Path

PG_USER = "hopkinson"
MISSING = "PostgreSQL server binaries (initdb, pg_ctl) not found: apt-get install postgresql"


class ClusterUnavailable(RuntimeError):
    """The server's binaries are missing (the reason says what to install)."""


def pg_bin() -> Path | None:
    found = shutil.which("pg_ctl")
    if found and shutil.which("initdb"):
        return Path(found).parent
    for folder in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True):
        if (Path(folder) / "initdb").exists() and (Path(folder) / "pg_ctl").exists():
            return Path(folder)
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def throwaway_cluster() -> Iterator[str]:
    """The URL of a new cluster's maintenance database; ClusterUnavailable without the binaries,
    RuntimeError (with the server's log) when it does not start."""
    bindir = pg_bin()
    if bindir is None:
        raise ClusterUnavailable(MISSING)
    as_root = os.geteuid() == 0
    prefix = ["runuser", "-u", "postgres", "--"] if as_root else []
    root = Path(tempfile.mkdtemp(prefix="hopkinson-pg-"))
    data, sock, log = root / "data", root / "socket", root / "server.log"
    sock.mkdir()
    if as_root:
        shutil.chown(root, "postgres")
        shutil.chown(sock, "postgres")
    port = _free_port()
    env = dict(os.environ, LC_ALL="C")
    try:
        subprocess.run([*prefix, str(bindir / "initdb"), "-D", str(data), "-U", PG_USER, "--auth=trust", "-E", "UTF8",
                        "--no-sync", "--no-instructions"], check=True, capture_output=True, timeout=120, env=env)
        options = f"-k {sock} -p {port} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=60"
        subprocess.run([*prefix, str(bindir / "pg_ctl"), "-D", str(data), "-o", options, "-l", str(log), "-w",
                        "-t", "60", "start"], check=True, capture_output=True, timeout=90, env=env)
    except (subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
        text = log.read_text() if log.exists() else ""
        shutil.rmtree(root, ignore_errors=True)
        raise RuntimeError(f"the throw-away PostgreSQL cluster did not start: {exc}; "
                           f"{getattr(exc, 'stderr', b'')!r} {text}") from None
    try:
        yield f"postgresql://{PG_USER}@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([*prefix, str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop"],
                       capture_output=True, timeout=60)
        shutil.rmtree(root, ignore_errors=True)


def new_postgres_database(server_url: str) -> str:
    """A fresh, empty database on the server; its URL."""
    import uuid

    import psycopg

    name = f"lab_{uuid.uuid4().hex[:12]}"
    with contextlib.closing(psycopg.connect(server_url, autocommit=True)) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    return server_url.rsplit("/", 1)[0] + f"/{name}"
