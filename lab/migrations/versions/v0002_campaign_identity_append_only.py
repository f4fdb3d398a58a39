"""Campaigns keyed by UUID, sensors' data and jobs as appended rows, certificate lineage, and
every table append-only in the database itself (UPDATE, DELETE and, on PostgreSQL, TRUNCATE
refused by triggers for every role; the rig's role has no such privilege either).

What a record written by 0001 becomes (no row of it is lost or changed but as said here):

- each sensor's model, owner, nominal sensitivity, unit, tolerance and interval become its first
  `sensor_data` row, dated the sensor's `created_utc`, actor "migration 0002";
- a sensor's serial is normalised as the software keys it from now on ("sn-7 " becomes SN-7),
  unless another sensor already has that serial (then it is left apart, and said);
- each campaign gets the UUID its run folder's journal gives (`campaign_uuid`, or for a journal
  from before campaign UUIDs the one rig.journal.legacy_campaign_uuid derives), so shots of
  that run folder recorded later join it; a new random UUID when the journal cannot be read at
  the campaign's recorded path from where the upgrade runs;
- each certificate: `campaign_id` the campaign its subject names, `specimen` when its prefix
  holds "-SIM", `revision` counting its campaign's certificates of its kind in the order they
  were issued, `replaces` NULL for 0001's "" (replaces nothing);
- 0001 let two certificates replace the same one; both are kept as issued, and every
  certificate from now on has one successor at most (a unique index on `replaces` that leaves
  out only those later legacy successors);
- one audit entry (action "schema upgraded", subject "0002") says what was done: the campaigns'
  UUIDs and where each came from, the serials normalised or left apart, the legacy second
  successors (none in a new, empty record).

The upgrade runs in one transaction (hopkinson.lab.database.upgrade_database): it happens whole
or not at all, on PostgreSQL and SQLite alike.

Revision ID: 0002
Revises: 0001
"""

from __future__ import annotations

import json
import sqlite3
import uuid
from datetime import UTC, datetime
from pathlib import Path

import sqlalchemy as sa
from alembic import op

revision = "0002"
down_revision = "0001"
branch_labels = None
depends_on = None

MESSAGE = "is append-only: rows are never updated or deleted"
TABLES = ("sensors", "sensor_data", "rigs", "reference_items", "campaigns", "jobs", "shots", "analyses",
          "certificates", "audit")
NAMING = {"uq": "uq_%(table_name)s_%(column_0_name)s"}  # names SQLite's unnamed constraints in batch mode


def _postgres() -> bool:
    return op.get_bind().dialect.name == "postgresql"


def _drop_old_triggers() -> None:
    for table in ("audit", "certificates"):
        if _postgres():
            op.execute(f"DROP TRIGGER {table}_append_only ON {table}")
            op.execute(f"DROP FUNCTION {table}_append_only()")
        else:
            op.execute(f"DROP TRIGGER {table}_no_update")
            op.execute(f"DROP TRIGGER {table}_no_delete")


def upgrade() -> None:
    bind = op.get_bind()
    _drop_old_triggers()
    op.create_table(
        "sensor_data",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("sensor_id", sa.Integer(), sa.ForeignKey("sensors.id"), nullable=False, index=True),
        sa.Column("utc", sa.String(40), nullable=False),
        sa.Column("actor", sa.String(200), nullable=False),
        sa.Column("model", sa.String(200), nullable=False),
        sa.Column("owner", sa.String(200), nullable=False),
        sa.Column("nominal_sensitivity", sa.Float(), nullable=True),
        sa.Column("sensitivity_unit", sa.String(40), nullable=False),
        sa.Column("tolerance_percent", sa.Float(), nullable=True),
        sa.Column("interval_days", sa.Integer(), nullable=True),
    )
    sensors = bind.execute(sa.text("SELECT id, model, owner, nominal_sensitivity, sensitivity_unit, "
                                   "tolerance_percent, interval_days, created_utc FROM sensors")).mappings().all()
    for s in sensors:
        bind.execute(sa.text("INSERT INTO sensor_data (sensor_id, utc, actor, model, owner, nominal_sensitivity, "
                             "sensitivity_unit, tolerance_percent, interval_days) VALUES (:id, :created_utc, "
                             "'migration 0002', :model, :owner, :nominal_sensitivity, :sensitivity_unit, "
                             ":tolerance_percent, :interval_days)"), dict(s))
    serials = _normalise_serials(bind)
    with op.batch_alter_table("sensors") as batch:
        for column in ("model", "owner", "nominal_sensitivity", "sensitivity_unit", "tolerance_percent",
                       "interval_days"):
            batch.drop_column(column)

    with op.batch_alter_table("campaigns", naming_convention=NAMING) as batch:
        batch.add_column(sa.Column("uuid", sa.String(36), nullable=True))
        batch.drop_constraint("campaigns_name_key" if _postgres() else "uq_campaigns_name", type_="unique")
    identities: dict[str, dict[str, str]] = {}
    for row in bind.execute(sa.text("SELECT id, name, path FROM campaigns ORDER BY id")).mappings().all():
        found = _journal_uuid(row["path"])
        value = found if found is not None and found not in identities else str(uuid.uuid4())
        identities[value] = {"campaign": row["name"], "path": row["path"],
                             "from": "run folder's journal" if value == found else
                             "new (run folder not found)" if found is None else "new (its journal's UUID was taken)"}
        bind.execute(sa.text("UPDATE campaigns SET uuid = :u WHERE id = :id"), {"u": value, "id": row["id"]})
    with op.batch_alter_table("campaigns") as batch:
        batch.alter_column("uuid", existing_type=sa.String(36), nullable=False)
        batch.create_unique_constraint("uq_campaigns_uuid", ["uuid"])

    op.create_table(
        "jobs",
        sa.Column("id", sa.Integer(), primary_key=True),
        sa.Column("campaign_id", sa.Integer(), sa.ForeignKey("campaigns.id"), nullable=False, index=True),
        sa.Column("utc", sa.String(40), nullable=False),
        sa.Column("actor", sa.String(200), nullable=False),
        *(sa.Column(name, sa.Text(), nullable=False) for name in (
            "condition", "location", "customer_contact", "mounting", "environment")),
        sa.Column("received", sa.String(20), nullable=False),
        sa.Column("customer", sa.String(200), nullable=False),
    )

    with op.batch_alter_table("shots") as batch:
        batch.alter_column("sensor_id", existing_type=sa.Integer(), nullable=True)
        batch.add_column(sa.Column("simulated_marks", sa.Text(), nullable=False, server_default=""))
        batch.add_column(sa.Column("context_json", sa.Text(), nullable=False, server_default="{}"))
    with op.batch_alter_table("analyses") as batch:
        batch.add_column(sa.Column("pulse_width_s", sa.Float(), nullable=True))

    with op.batch_alter_table("certificates", naming_convention=NAMING) as batch:
        batch.add_column(sa.Column("campaign_id", sa.Integer(), nullable=True))
        batch.add_column(sa.Column("specimen", sa.Boolean(), nullable=False, server_default=sa.false()))
        batch.add_column(sa.Column("revision", sa.Integer(), nullable=False, server_default="0"))
        batch.alter_column("replaces", existing_type=sa.String(40), nullable=True)
    bind.execute(sa.text("UPDATE certificates SET replaces = NULL WHERE replaces = ''"))
    rows = bind.execute(sa.text("SELECT c.id, c.prefix, k.id AS campaign_id FROM certificates c "
                                "LEFT JOIN campaigns k ON k.name = c.subject ORDER BY c.id")).mappings().all()
    revisions: dict[tuple[int | None, bool], int] = {}
    for row in rows:
        specimen = "-SIM" in row["prefix"]
        key = (row["campaign_id"], specimen)
        revisions[key] = revisions.get(key, -1) + 1
        bind.execute(sa.text("UPDATE certificates SET campaign_id = :c, specimen = :s, revision = :r WHERE id = :id"),
                     {"c": row["campaign_id"], "s": specimen, "r": revisions[key], "id": row["id"]})
    with op.batch_alter_table("certificates") as batch:
        batch.create_foreign_key("fk_certificates_campaign", "campaigns", ["campaign_id"], ["id"])
        batch.create_index("ix_certificates_campaign_id", ["campaign_id"])
        batch.create_unique_constraint("uq_certificates_lineage", ["campaign_id", "specimen", "revision"])
    later = bind.execute(sa.text("SELECT c.id, c.number, c.replaces FROM certificates c WHERE c.replaces IS NOT NULL "
                                 "AND EXISTS (SELECT 1 FROM certificates e WHERE e.replaces = c.replaces AND e.id < c.id) "
                                 "ORDER BY c.id")).mappings().all()
    where = sa.text(f"id NOT IN ({', '.join(str(int(r['id'])) for r in later)})") if later else None
    op.create_index("uq_certificates_replaces", "certificates", ["replaces"], unique=True,
                    sqlite_where=where, postgresql_where=where)

    for table in TABLES:
        _append_only(table)
    if not (sensors or identities or rows):
        return  # a new, empty record: nothing was migrated
    bind.execute(sa.text("INSERT INTO audit (utc, actor, action, subject, detail) VALUES (:utc, 'migration 0002', "
                         "'schema upgraded', '0002', :detail)"),
                 {"utc": datetime.now(UTC).isoformat(timespec="microseconds").replace("+00:00", "Z"),
                  "detail": json.dumps({"from": "0001", "campaign_uuids": identities, **serials,
                                        "second_successors": {r["number"]: r["replaces"] for r in later}},
                                       sort_keys=True)})


def _normalise_serials(bind: sa.Connection) -> dict[str, dict[str, str]]:
    """Serials as the software keys them from 0002 on (hopkinson.lab.records.normal_serial,
    frozen here: spaces collapsed, upper case), so a sensor 0001 recorded as "sn-7 " is found
    as SN-7. A serial whose normal form another sensor already has is left as it was (its
    history apart: merging would move shots between sensors). What was done, for the audit."""
    rows = bind.execute(sa.text("SELECT id, serial FROM sensors ORDER BY id")).all()
    taken = {serial for _id, serial in rows}
    renamed, apart = {}, {}
    for sensor_id, serial in rows:
        normal = " ".join(serial.split()).upper()
        if normal == serial or not normal:
            continue
        if normal in taken:
            apart[serial] = normal
            continue
        bind.execute(sa.text("UPDATE sensors SET serial = :n WHERE id = :id"), {"n": normal, "id": sensor_id})
        taken.add(normal)
        renamed[serial] = normal
    return {"serials_normalised": renamed, "serials_left_apart": apart}


def _journal_uuid(run_folder: str) -> str | None:
    """The campaign UUID a run folder's journal gives (None: no readable journal there). Frozen
    here as rig.journal.read_campaign_uuid and legacy_campaign_uuid had it when 0002 was written
    (a migration never changes with the software; tests/lab/test_migration.py holds them equal)."""
    if not run_folder:
        return None
    try:
        journal = Path(run_folder).resolve() / "journal.sqlite"
        if not journal.is_file():
            return None
        connection = sqlite3.connect(journal.as_uri() + "?mode=ro", uri=True)
        try:
            meta = dict(connection.execute("SELECT key, value FROM meta").fetchall())
        finally:
            connection.close()
    except (OSError, ValueError, sqlite3.Error):
        return None
    value = meta.get("campaign_uuid") or (
        str(uuid.uuid5(uuid.NAMESPACE_URL, f"hopkinson-campaign:{meta.get('created_utc')}|{meta.get('plan_fingerprint')}"))
        if "created_utc" in meta else None)
    try:
        return value if value and uuid.UUID(value) else None
    except ValueError:
        return None


def _append_only(table: str) -> None:
    """Refuse UPDATE, DELETE (and TRUNCATE on PostgreSQL) on `table` inside the database."""
    message = f"{table} {MESSAGE}"
    if _postgres():
        op.execute("CREATE OR REPLACE FUNCTION hopkinson_append_only() RETURNS trigger LANGUAGE plpgsql AS $$ "
                   f"BEGIN RAISE EXCEPTION '% {MESSAGE}', TG_TABLE_NAME; END $$")
        op.execute(f"CREATE TRIGGER {table}_append_only BEFORE UPDATE OR DELETE ON {table} "
                   f"FOR EACH ROW EXECUTE FUNCTION hopkinson_append_only()")
        op.execute(f"CREATE TRIGGER {table}_no_truncate BEFORE TRUNCATE ON {table} "
                   f"FOR EACH STATEMENT EXECUTE FUNCTION hopkinson_append_only()")
    else:
        for verb in ("UPDATE", "DELETE"):
            op.execute(f"CREATE TRIGGER {table}_no_{verb.lower()} BEFORE {verb} ON {table} "
                       f"BEGIN SELECT RAISE(ABORT, '{message}'); END")


def downgrade() -> None:
    raise NotImplementedError("the lab record is append-only: restore a backup taken before `lab upgrade`")
