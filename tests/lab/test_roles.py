"""The record's immutability in a real PostgreSQL: an owner role migrates, the rig's role
(granted by `hopkinson lab grants`) records shots and issues certificates but can neither
change, delete, truncate nor disable a trigger, and cannot migrate."""

from __future__ import annotations

import contextlib

import psycopg
import pytest
import sqlalchemy as sa

from hopkinson.lab.errors import LabError
from hopkinson.lab.repository import open_repository
from hopkinson.lab.roles import grants_sql
from hopkinson.rig.cli.main import main
from tests.lab.records import made_up_record
from tests.lab.test_repository import issue_for


def _as(url: str, role: str) -> str:
    return url.replace("postgresql://hopkinson@", f"postgresql://{role}@")


def test_the_rig_role_inserts_and_selects_only(postgres_server: str, tmp_path, capsys) -> None:
    from tests.lab.pg_cluster import new_postgres_database

    url = new_postgres_database(postgres_server)
    name = url.rsplit("/", 1)[1]
    with contextlib.closing(psycopg.connect(url, autocommit=True)) as db:
        for role in ("lab_owner", "lab_rig"):
            db.execute(f"DO $$ BEGIN IF NOT EXISTS (SELECT FROM pg_roles WHERE rolname = '{role}') THEN "
                       f"CREATE ROLE {role} LOGIN; END IF; END $$")
        db.execute(f"GRANT CONNECT, CREATE ON DATABASE {name} TO lab_owner")
        db.execute("GRANT CREATE ON SCHEMA public TO lab_owner")
    owner, rig = _as(url, "lab_owner"), _as(url, "lab_rig")
    with pytest.raises(LabError, match="run `hopkinson lab upgrade` as the database's owner role"):
        open_repository(rig)  # the rig's role cannot create the schema
    assert main(["lab", "upgrade", "--database", owner, "--config", "config/rig-sim.toml"]) == 0
    with contextlib.closing(psycopg.connect(url, autocommit=True)) as db:
        db.execute(grants_sql("lab_rig", "lab_owner"))
    with open_repository(rig) as repo:  # the rig's work: record, register, issue
        repo.record_shot(made_up_record(campaign="run-1"))
        repo.register_sensor("SN-7", "Q", owner="ACME")
        issue_for(repo, "run-1", {"customer": "ACME"})
        for statement in ("UPDATE analyses SET sensitivity = 2", "DELETE FROM shots", "TRUNCATE audit",
                          "ALTER TABLE audit DISABLE TRIGGER ALL", "DROP TABLE certificates",
                          "INSERT INTO alembic_version VALUES ('9999')", "CREATE TABLE mine (x int)"):
            with pytest.raises(sa.exc.DBAPIError, match="permission denied|must be owner"), \
                    repo.engine.begin() as connection:
                connection.execute(sa.text(statement))
        assert repo.counts()["certificates"] == 1 and repo.counts()["shots"] == 1
    capsys.readouterr()
    assert main(["lab", "upgrade", "--database", rig, "--config", "config/rig-sim.toml"]) == 0  # already current
    with open_repository(owner) as repo, pytest.raises(sa.exc.DBAPIError, match="append-only"), \
            repo.engine.begin() as connection:  # the owner too meets the triggers
        connection.execute(sa.text("UPDATE analyses SET sensitivity = 2"))
