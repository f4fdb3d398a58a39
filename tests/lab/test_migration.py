"""A lab's real record upgraded: a database at schema 0001, filled through plain SQL the way
version 0001 of the software wrote it (sensors with their data, campaigns, shots, analyses,
certificates with re-issues and a specimen, the audit trail, 0001's triggers in place), then
`hopkinson lab upgrade`. Nothing is lost or changed; what 0002 adds is what its rules say,
worked out here by hand; every table refuses UPDATE and DELETE (and TRUNCATE on PostgreSQL)
afterwards; an upgrade that fails leaves the database as it was; a backup comes first."""

from __future__ import annotations

import hashlib
import json
import sqlite3
import uuid
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa
from alembic import command

from hopkinson.lab.database import _alembic_config, current_revision, head_revision, make_engine
from hopkinson.lab.repository import open_repository
from hopkinson.lab.schema import APPEND_ONLY_TABLES
from hopkinson.rig.cli.main import main
from tests.lab.records import made_up_record
from tests.lab.test_repository import issue_for

REPO = Path(__file__).resolve().parents[2]
CONFIG = str(REPO / "config" / "rig-sim.toml")
SENSOR_FIELDS = ("model", "owner", "nominal_sensitivity", "sensitivity_unit", "tolerance_percent", "interval_days")
FIGURES = [key + part for key in ("sensitivity", "shock_sensitivity", "natural_frequency_hz", "damping_ratio",
                                  "fbsd_5_hz", "fbsd_10_hz") for part in ("", "_u", "_lo", "_hi")]
PLAN = """
name = "legacy"
operator = "tech A"
[accelerometer]
model = "ACC-20k"
serial = "SN-7"
[[shots]]
pressure_bar = 2.0
repeats = 3
projectile = 3
"""


def at_0001(url: str) -> sa.Engine:
    """A new database brought to schema 0001 only, as version 0001 of the software left it."""
    engine = make_engine(url)
    with engine.connect() as connection, connection.begin():
        command.upgrade(_alembic_config(connection), "0001")
    return engine


def insert(connection: sa.Connection, table: str, row: dict[str, Any]) -> int:
    """One row by plain SQL (the id drawn by the database, as the ORM of 0001 let it); its id."""
    names = ", ".join(row)
    marks = ", ".join(f":{k}" for k in row)
    return connection.execute(sa.text(f"INSERT INTO {table} ({names}) VALUES ({marks}) RETURNING id"), row).scalar_one()


def legacy_run_folder(parent: Path) -> tuple[Path, str]:
    """A run folder whose journal predates campaign UUIDs (its `campaign_uuid` meta row removed,
    as 0001's journals had none); its folder and the UUID the software derives for it."""
    from hopkinson.rig.journal import Journal, read_campaign_uuid
    from hopkinson.rig.run_folder import create_run_folder

    plan = parent / "legacy.toml"
    parent.mkdir(parents=True, exist_ok=True)
    plan.write_text(PLAN)
    run = create_run_folder(plan, parent / "a", name="run-2026-03")
    with Journal.open(run):
        pass
    with sqlite3.connect(run.path / "journal.sqlite") as db:
        db.execute("DELETE FROM meta WHERE key = 'campaign_uuid'")
    derived = read_campaign_uuid(run.path / "journal.sqlite")
    assert derived is not None
    return run.path, derived


def fill_0001(connection: sa.Connection, run_folder: Path) -> dict[str, list[dict[str, Any]]]:
    """A record as 0001 wrote it; every row inserted, by table, each with its id."""
    rows: dict[str, list[dict[str, Any]]] = {}

    def add(table: str, **row: Any) -> int:
        row = dict(row)
        row["id"] = insert(connection, table, row)
        rows.setdefault(table, []).append(row)
        return row["id"]

    def audit(utc: str, actor: str, action: str, about: str, /, **detail: Any) -> None:
        add("audit", utc=utc, actor=actor, action=action, subject=about,
            detail=json.dumps(detail, sort_keys=True) if detail else "")

    hb1, hb2 = add("rigs", name="HB-1"), add("rigs", name="HB-2")
    add("reference_items", rig_id=hb1, item="laser Doppler interferometer (grating pitch)",
        certificate="PTB-2025-0815", issued_by="PTB", u_rel=1e-4, due="2030-06-30")
    add("reference_items", rig_id=hb2, item="digitizer gain", certificate="DKD-1", issued_by="", u_rel=None, due="")
    sensor = {}
    for serial, model, owner, nominal, unit, tolerance, interval, created in (
            ("SN-7", "ACC-20k", "ACME Aerospace", 0.1234567890123, "mV/g", 2.0, 365, "2025-01-10T08:00:00.000001Z"),
            ("SN-8", "ACC-60k", "", None, "", None, None, "2025-02-11T09:30:00.250000Z"),
            ("SN-9", "", "Bar Labs", 2.5e-7, "V/(m/s²)", 0.5, 730, "2025-03-12T10:45:00.999999Z"),
            ("", "", "", None, "", None, None, "2025-04-13T11:00:00.000000Z"),  # 0001's sensor of serial-less shots
            ("sn-10 ", "ACC-20k", "", None, "", None, None, "2025-05-14T12:00:00.5Z"),  # 0001 kept serials as typed
            ("sn-7", "", "", None, "", None, None, "2025-06-15T13:00:00.5Z")):  # SN-7 spelled otherwise
        sensor[serial] = add("sensors", serial=serial, model=model, owner=owner, nominal_sensitivity=nominal,
                             sensitivity_unit=unit, tolerance_percent=tolerance, interval_days=interval,
                             created_utc=created)
        if owner:
            audit(created, "Q. Manager", "sensor updated", serial, owner=owner)

    campaign = {}
    for name, rig, serial, path, first in (
            ("run-2026-03", hb1, "SN-7", str(run_folder), "2026-03-01T10:00:00Z"),
            ("camp", hb1, "SN-8", "/srv/runs/a/camp", "2026-03-05T09:00:00Z"),
            ("run-2026-04", hb2, "SN-9", "/srv/runs/run-2026-04", "2026-04-01T08:00:00Z")):
        campaign[name] = add("campaigns", name=name, rig_id=rig, sensor_id=sensor[serial], path=path, first_utc=first)
    with pytest.raises(sa.exc.IntegrityError), connection.begin_nested():  # 0001: one campaign per name, ever
        insert(connection, "campaigns", {"name": "camp", "rig_id": hb1, "sensor_id": sensor["SN-8"],
                                         "path": "/srv/runs/b/camp", "first_utc": "2026-03-06T09:00:00Z"})

    n = 0
    for name, serial, rig, shots in (("run-2026-03", "SN-7", hb1, 3), ("camp", "SN-8", hb1, 4),
                                     ("run-2026-04", "SN-9", hb2, 2), (None, "", hb2, 1), (None, "SN-7", hb1, 1),
                                     (None, "sn-10 ", hb1, 2), (None, "sn-7", hb2, 1)):
        for i in range(shots):
            n += 1
            uid = str(uuid.uuid5(uuid.NAMESPACE_URL, f"legacy-shot-{n}"))
            utc = f"2026-0{3 + n % 2}-{10 + n:02d}T1{n % 10}:00:00.{n:06d}Z"
            # 0001 merged runs into a campaign by name: camp's last shots came from b/camp
            folder = run_folder if name == "run-2026-03" else Path("/srv/runs") / ("b" if name == "camp" and i > 1
                                                                                 else "a") / (name or "lone")
            shot = add("shots", uuid=uid, raw_sha256=hashlib.sha256(uid.encode()).hexdigest(),
                       sensor_id=sensor[serial], rig_id=rig, campaign_id=campaign[name] if name else None,
                       shot_name=f"s{n:03d}", operator="tech A" if n % 3 else "tech Ä", utc_time=utc,
                       pressure_bar=1.5 + 0.25 * n, projectile=1 + n % 3, simulated=name == "camp",
                       software_version="0.1.0", path=str(folder / "shots" / f"s{n:03d}.h5"),
                       recorded_utc=utc.replace("T1", "T2"))
            audit(utc, "tech A", "shot fired", uid, serial=serial, path=str(folder / f"s{n:03d}.h5"),
                  raw_sha256=hashlib.sha256(uid.encode()).hexdigest(), campaign=name or "")
            states = ["analysed"] if n % 4 else ["raw"]
            if n == 2:
                states = ["analysis_failed", "analysed"]  # a failed analysis, then a re-analysis
            for k, state in enumerate(states):
                figures = {f: (1.0 + n * 1e-3 + j * 1.1e-7 if state == "analysed" and not f.startswith("fbsd_10")
                               else None) for j, f in enumerate(FIGURES)}
                add("analyses", shot_id=shot, file_sha256=hashlib.sha256(f"{uid}/{k}".encode()).hexdigest(),
                    state=state, error="identification did not converge" if state == "analysis_failed" else "",
                    analysed_utc=utc if state != "raw" else "", software_version="0.1.0" if state != "raw" else "",
                    response_unit="m/s^2" if state == "analysed" else "",
                    peak_acceleration_m_s2=4.9e5 + n if state == "analysed" else None, recorded_utc=utc,
                    **figures)
                audit(utc, "tech A", "result recorded", uid, file_sha256=f"{uid}/{k}", state=state)

    for number, replaces, subject, serial, issued in (
            ("HB-2026-0001", "", "run-2026-03", "SN-7", "2026-03-20T09:00:00.000001Z"),
            ("HB-2026-0002", "HB-2026-0001", "run-2026-03", "SN-7", "2026-03-21T09:00:00.000002Z"),
            ("HB-SIM-2026-0001", "", "camp", "SN-8", "2026-03-22T09:00:00.000003Z"),
            ("HB-2026-0003", "", "run-2026-04", "SN-9", "2026-04-20T09:00:00.000004Z"),
            ("HB-2026-0004", "", "run-2026-04", "SN-9", "2026-04-21T09:00:00.000005Z"),  # 0001: a second first issue
            ("HB-SIM-2026-0002", "HB-SIM-2026-0001", "camp", "SN-8", "2026-04-22T09:00:00.000006Z"),
            ("HB-2026-0005", "HB-2026-0001", "run-2026-03", "SN-7", "2026-04-23T09:00:00.000007Z")):  # 0001: a 2nd successor
        prefix, year, sequence = number.rsplit("-", 2)
        content = json.dumps({"number": number, "issued_utc": issued, "replaces": replaces, "serial": serial,
                              "customer": "ACME Aerospace", "conformity": "pass"}, sort_keys=True)
        add("certificates", number=number, prefix=prefix, year=int(year), sequence=int(sequence), replaces=replaces,
            sensor_id=sensor[serial], subject=subject, customer="ACME Aerospace", authorised_by="Dr. Q. Manager",
            issued_utc=issued, decision_rule="guarded", conformity="pass", content_json=content,
            content_sha256=hashlib.sha256(content.encode()).hexdigest())
        audit(issued, "Dr. Q. Manager", "certificate replaced" if replaces else "certificate issued", number,
              serial=serial, subject=subject, replaces=replaces)
    return rows


# The lineage migration 0002's rules give these certificates (its docstring): the campaign whose
# name the certificate's subject is, a specimen when its prefix holds "-SIM", the revision
# counting the campaign's certificates of that kind in the order they were issued, and NULL for
# 0001's "" (replaces nothing). Worked out by hand from the rows above.
LINEAGE = {
    "HB-2026-0001": ("run-2026-03", False, 0, None),
    "HB-2026-0002": ("run-2026-03", False, 1, "HB-2026-0001"),
    "HB-SIM-2026-0001": ("camp", True, 0, None),
    "HB-2026-0003": ("run-2026-04", False, 0, None),
    "HB-2026-0004": ("run-2026-04", False, 1, None),
    "HB-SIM-2026-0002": ("camp", True, 1, "HB-SIM-2026-0001"),
    "HB-2026-0005": ("run-2026-03", False, 2, "HB-2026-0001"),
}


def table_rows(connection: sa.Connection, table: str) -> dict[int, dict[str, Any]]:
    return {r["id"]: dict(r) for r in connection.execute(sa.text(f"SELECT * FROM {table} ORDER BY id")).mappings()}


@pytest.fixture
def legacy(lab_url: str, tmp_path: Path) -> tuple[str, dict[str, list[dict[str, Any]]], str]:
    """(URL, the rows inserted, the legacy run folder's derived campaign UUID)."""
    run, derived = legacy_run_folder(tmp_path / "runs")
    engine = at_0001(lab_url)
    with engine.begin() as connection:
        rows = fill_0001(connection, run)
    with pytest.raises(sa.exc.DBAPIError, match="append-only"), engine.begin() as connection:
        connection.execute(sa.text("UPDATE audit SET actor = 'someone else'"))  # 0001's triggers hold
    engine.dispose()
    return lab_url, rows, derived


def upgrade(url: str, capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[int, str, str]:
    backup = ("--yes-i-have-a-backup",) if url.startswith("postgresql") else ()
    code = main(["lab", "upgrade", "--database", url, "--config", CONFIG, *backup, *extra])
    out, err = capsys.readouterr()
    return code, out, err


def test_a_populated_0001_record_upgrades_with_nothing_lost_or_changed(
        legacy: tuple[str, dict[str, list[dict[str, Any]]], str], capsys: pytest.CaptureFixture[str]) -> None:
    url, inserted, derived = legacy
    with pytest.raises(Exception, match="older than this software's.*lab upgrade"):
        open_repository(url)  # first use never migrates a record silently
    code, out, err = upgrade(url, capsys)
    assert code == 0, err
    assert f"schema 0001 -> {head_revision()}" in out

    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            after = {table: table_rows(connection, table) for table in APPEND_ONLY_TABLES}
        assert current_revision(engine) == head_revision()
    finally:
        engine.dispose()

    # the migration's own audit entry, the one row it adds to a table 0001 had
    (entry,) = [a for a in after["audit"].values() if a["id"] > max(r["id"] for r in inserted["audit"])]
    assert (entry["actor"], entry["action"], entry["subject"]) == ("migration 0002", "schema upgraded", "0002")
    told = json.loads(entry["detail"])
    assert told["second_successors"] == {"HB-2026-0005": "HB-2026-0001"}
    assert told["serials_normalised"] == {"sn-10 ": "SN-10"} and told["serials_left_apart"] == {"sn-7": "SN-7"}
    for line in ("sensor 'sn-10 ' is now SN-10 (serials are normalised)",
                 "sensor 'sn-7' kept apart from sensor SN-7, which the record already had: `lab sensor SN-7` shows "
                 "SN-7's shots only",
                 "campaigns: 1 took the UUID their run folder's journal gives, 2 a new one (run folder not found from "
                 "here); `hopkinson lab audit --subject 0002 --json` lists them",
                 "certificate HB-2026-0005 replaced HB-2026-0001, which another certificate had replaced before (0001 "
                 "allowed it): both kept as issued"):
        assert line in out.splitlines(), out
    assert {v["campaign"]: v["from"] for v in told["campaign_uuids"].values()} == {
        "run-2026-03": "run folder's journal", "camp": "new (run folder not found)",
        "run-2026-04": "new (run folder not found)"}
    del after["audit"][entry["id"]]

    moved = set(SENSOR_FIELDS)
    for table, rows in inserted.items():
        assert sorted(after[table]) == [r["id"] for r in rows], table  # every row, none added
        for row in rows:
            now = after[table][row["id"]]
            kept = {k: v for k, v in row.items() if not (table == "sensors" and k in moved)
                    and not (table == "certificates" and k == "replaces")}
            if table == "sensors" and row["serial"] == "sn-10 ":
                kept["serial"] = "SN-10"  # normalised: the one value 0002 changes besides replaces '' -> NULL
            assert {k: now[k] for k in kept} == kept, (table, row["id"])
    assert {k for k in after["sensors"][1]} == {"id", "serial", "created_utc"}

    # the sensors' data: one row each, as of the sensor's creation
    by_sensor = {d["sensor_id"]: d for d in after["sensor_data"].values()}
    assert len(by_sensor) == len(after["sensor_data"]) == len(inserted["sensors"])
    for s in inserted["sensors"]:
        data = by_sensor[s["id"]]
        assert {k: data[k] for k in SENSOR_FIELDS} == {k: s[k] for k in SENSOR_FIELDS}
        assert data["utc"] == s["created_utc"] and data["actor"] == "migration 0002"

    # the new columns of kept rows
    assert all(s["simulated_marks"] == "" and s["context_json"] == "{}" for s in after["shots"].values())
    assert all(a["pulse_width_s"] is None for a in after["analyses"].values())
    assert after["jobs"] == {}

    # campaigns: each a distinct valid UUID; the legacy run folder's the one its journal gives
    uuids = {c["name"]: c["uuid"] for c in after["campaigns"].values()}
    assert len(set(uuids.values())) == len(uuids) == 3
    for value in uuids.values():
        assert str(uuid.UUID(value)) == value
    assert uuids["run-2026-03"] == derived  # rig.journal's derivation, which the migration keeps a frozen copy of
    assert set(told["campaign_uuids"]) == set(uuids.values())

    # certificate lineage
    campaign_id = {c["name"]: c["id"] for c in after["campaigns"].values()}
    lineage = {c["number"]: (c["campaign_id"], bool(c["specimen"]), c["revision"], c["replaces"])
               for c in after["certificates"].values()}
    assert lineage == {number: (campaign_id[name], specimen, revision, replaces)
                       for number, (name, specimen, revision, replaces) in LINEAGE.items()}


def test_after_the_upgrade_every_table_refuses_update_delete_and_truncate(
        legacy: tuple[str, dict[str, list[dict[str, Any]]], str], capsys: pytest.CaptureFixture[str]) -> None:
    url, _inserted, _derived = legacy
    assert upgrade(url, capsys)[0] == 0
    engine = make_engine(url)
    try:
        with engine.begin() as connection:  # a job row, so that jobs has a row to refuse changing
            connection.execute(sa.text(
                "INSERT INTO jobs (campaign_id, utc, actor, condition, location, customer_contact, mounting, "
                "environment, received, customer) VALUES (1, '2026-05-01T00:00:00Z', 'Q', 'as new', 'lab', '', '', "
                "'', '2026-04-30', '')"))
        postgres = engine.dialect.name == "postgresql"
        for table in APPEND_ONLY_TABLES:
            with engine.connect() as connection:
                assert connection.execute(sa.text(f"SELECT count(*) FROM {table}")).scalar_one() > 0, table
            statements = [f"UPDATE {table} SET id = id", f"DELETE FROM {table}"]
            if postgres:
                statements.append(f"TRUNCATE {table} CASCADE")
            for statement in statements:
                with pytest.raises(sa.exc.DBAPIError, match="append-only"), engine.begin() as connection:
                    connection.execute(sa.text(statement))
    finally:
        engine.dispose()


def test_the_upgraded_record_works_on(legacy: tuple[str, dict[str, list[dict[str, Any]]], str],
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The software of today on the upgraded record: the sensor's data as 0001 had it, a new shot
    of the legacy run folder joins its campaign (its journal's UUID), re-issue rules hold on the
    lineage the migration gave, and the database refuses a third successor of one certificate."""
    url, _inserted, derived = legacy
    assert upgrade(url, capsys)[0] == 0
    with open_repository(url) as repo:
        info = repo.sensor("SN-7")
        assert (info.model, info.owner, info.nominal_sensitivity, info.tolerance_percent, info.interval_days) == \
            ("ACC-20k", "ACME Aerospace", 0.1234567890123, 2.0, 365)
        assert [r.shot_name for r in repo.shot_results("sn-10")] == ["s013"]  # by its normal serial (s012: raw)
        before = repo.counts()
        assert repo.record_shot(made_up_record("SN-7", campaign="run-2026-03", campaign_uuid=derived)) == "new"
        assert repo.counts()["campaigns"] == before["campaigns"]  # the resumed campaign is the same one
        with pytest.raises(Exception, match="HB-2026-0005 is valid"):
            issue_for(repo, "run-2026-03")
        with pytest.raises(Exception, match="HB-2026-0002: not the campaign's valid one.*only the valid certificate "
                                            "HB-2026-0005 can be replaced"):
            issue_for(repo, derived, replaces="HB-2026-0002")  # 0001's other successor of HB-2026-0001
        reissued = issue_for(repo, derived, replaces="HB-2026-0005")
        assert reissued.replaces == "HB-2026-0005"
        with pytest.raises(sa.exc.IntegrityError), repo.engine.begin() as connection:
            connection.execute(sa.text(
                "INSERT INTO certificates (number, prefix, year, sequence, replaces, sensor_id, campaign_id, specimen, "
                "revision, subject, customer, authorised_by, issued_utc, decision_rule, conformity, content_json, "
                "content_sha256) SELECT 'X-1', prefix, year, 99, 'HB-2026-0001', sensor_id, campaign_id, specimen, 9, "
                "subject, '', 'Q', issued_utc, '', '', '{}', '' FROM certificates WHERE number = 'HB-2026-0001'"))


def snapshot(url: str) -> dict[str, Any]:
    """Everything a record at 0001 is: its tables' columns and rows, its triggers, its version."""
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            inspector = sa.inspect(connection)
            tables = sorted(inspector.get_table_names())
            triggers = connection.execute(sa.text(
                "SELECT tgname FROM pg_trigger WHERE NOT tgisinternal" if engine.dialect.name == "postgresql"
                else "SELECT name FROM sqlite_master WHERE type = 'trigger'")).scalars().all()
            return {"tables": {t: ([c["name"] for c in inspector.get_columns(t)],
                                   connection.execute(sa.text(f"SELECT * FROM {t}")).mappings().all())
                               for t in tables}, "triggers": sorted(triggers)}
    finally:
        engine.dispose()


def test_a_backup_comes_first(legacy: tuple[str, dict[str, list[dict[str, Any]]], str], tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    """SQLite: a whole copy beside the file, at 0001 as it was. PostgreSQL: nothing changes until
    the owner says a backup exists; the pg_dump the command prints restores the record whole."""
    import shlex
    import subprocess

    url, _inserted, _derived = legacy
    before = snapshot(url)
    assert before["tables"]["alembic_version"][1] == [{"version_num": "0001"}]
    if url.startswith("sqlite"):
        code, out, err = upgrade(url, capsys)
        assert code == 0, err
        (copy,) = tmp_path.glob("lab.schema-0001.*.sqlite")
        assert f"backup taken before: {copy}" in out.splitlines()
        assert snapshot(f"sqlite:///{copy}") == before
        return
    code = main(["lab", "upgrade", "--database", url, "--config", CONFIG])
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1 and "back it up first" in err and "--yes-i-have-a-backup" in err, err
    assert snapshot(url) == before  # nothing changed
    dump = err[err.index("(pg_dump ") + 1:err.index("), then run")]
    assert shlex.split(dump)[-1] == url  # the database's URL, no password
    subprocess.run(shlex.split(dump), cwd=tmp_path, check=True, capture_output=True, timeout=120)
    (file,) = tmp_path.glob("lab.schema-0001.*.dump")
    from tests.lab.pg_cluster import new_postgres_database

    restored = new_postgres_database(url.rsplit("/", 1)[0] + "/postgres")
    subprocess.run(["pg_restore", "--no-owner", f"--dbname={restored}", str(file)], check=True, capture_output=True,
                   timeout=120)
    assert snapshot(restored) == before  # the backup is the record, whole
    code, out, err = upgrade(url, capsys)
    assert code == 0 and "lab grants" in out, err


def test_an_upgrade_that_fails_part_way_leaves_the_record_as_it_was(
        legacy: tuple[str, dict[str, list[dict[str, Any]]], str], tmp_path: Path,
        capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The last statement of migration 0002 fails (every row already moved, every table but
    one already guarded): the database is at 0001 as it was, and the user is told so."""
    import alembic.op

    url, _inserted, _derived = legacy
    before = snapshot(url)
    execute = alembic.op.execute
    failed = []

    def failing_at_the_end(sql: Any, *args: Any, **kwargs: Any) -> Any:
        if "TRIGGER audit_" in str(sql) and not failed:
            failed.append(sql)
            sql = "SELECT broken FROM no_such_table"  # the server's own error, mid-transaction
        return execute(sql, *args, **kwargs)

    monkeypatch.setattr(alembic.op, "execute", failing_at_the_end)
    code, out, err = upgrade(url, capsys)
    assert failed and code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert "failed and was undone: the database is as it was, at schema 0001" in err and "no_such_table" in err
    if url.startswith("sqlite"):
        (copy,) = tmp_path.glob("lab.schema-0001.*.sqlite")
        assert f"the backup taken before is {copy}" in err
    assert snapshot(url) == before
    monkeypatch.setattr(alembic.op, "execute", execute)
    assert upgrade(url, capsys)[0] == 0  # once the cause is gone, the upgrade goes through


def test_a_newer_record_is_neither_backed_up_nor_touched(lab_url: str, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    engine = at_0001(lab_url)
    with engine.begin() as connection:
        connection.execute(sa.text("UPDATE alembic_version SET version_num = '0042'"))
    engine.dispose()
    before = snapshot(lab_url)
    code, _out, err = upgrade(lab_url, capsys)
    assert code == 2 and "schema version 0042 is newer than this software's" in err and "nothing changed" in err
    assert snapshot(lab_url) == before and not list(tmp_path.glob("lab.schema-*"))
