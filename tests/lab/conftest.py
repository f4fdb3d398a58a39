"""The lab's record on both of its databases: SQLite (a file per test) and a real PostgreSQL
server, a throw-away cluster started once per session (tests/lab/pg_cluster.py). Each test
gets a database of its own. Without the server's binaries the PostgreSQL cases skip, naming
what to install."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.lab.pg_cluster import ClusterUnavailable, new_postgres_database, throwaway_cluster
from tests.rig.conftest import make_rig  # noqa: F401 (the simulated rig's fixture, for the recorder's tests)


@pytest.fixture(scope="session")
def postgres_server() -> Iterator[str]:
    """The URL of the session's throw-away PostgreSQL cluster's maintenance database."""
    try:
        cluster = throwaway_cluster()
        url = cluster.__enter__()
    except ClusterUnavailable as exc:
        pytest.skip(str(exc))
    except RuntimeError as exc:
        pytest.fail(str(exc))
    try:
        yield url
    finally:
        cluster.__exit__(None, None, None)


@pytest.fixture(params=["sqlite", "postgresql"])
def lab_url(request: pytest.FixtureRequest, tmp_path: Path) -> str:
    """An empty lab database of each kind (the same tests run on both)."""
    if request.param == "sqlite":
        return f"sqlite:///{tmp_path / 'lab.sqlite'}"
    return new_postgres_database(request.getfixturevalue("postgres_server"))
