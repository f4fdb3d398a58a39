"""The database roles of a lab's PostgreSQL (docs/lab-record.md): an owner role that owns the
tables and runs `hopkinson lab upgrade`, and the rig's role, which can INSERT and SELECT only.
Every table is append-only by its triggers too (migration 0002), so even the owner's
UPDATE, DELETE and TRUNCATE are refused unless it drops them (which only it, or a superuser,
can; an ALTER TABLE … DISABLE TRIGGER needs ownership, which the rig's role never has)."""

from __future__ import annotations

from hopkinson.lab.schema import APPEND_ONLY_TABLES


def _ident(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def grants_sql(rig_role: str, owner_role: str = "") -> str:
    """The SQL a DBA runs (as a superuser or the owner, once after each `lab upgrade`) so that
    `rig_role` can INSERT and SELECT only."""
    rig = _ident(rig_role)
    tables = ", ".join(APPEND_ONLY_TABLES)
    lines = [
        f"-- the rig's role {rig_role}: INSERT and SELECT only (hopkinson lab grants)",
        "REVOKE CREATE ON SCHEMA public FROM PUBLIC;",
        f"REVOKE ALL ON ALL TABLES IN SCHEMA public FROM {rig};",
        f"REVOKE ALL ON ALL SEQUENCES IN SCHEMA public FROM {rig};",
        f"GRANT USAGE ON SCHEMA public TO {rig};",
        f"GRANT SELECT, INSERT ON {tables} TO {rig};",
        f"GRANT SELECT ON alembic_version TO {rig};",
        f"GRANT USAGE ON ALL SEQUENCES IN SCHEMA public TO {rig};",
    ]
    if owner_role:
        owner = _ident(owner_role)
        lines += [f"ALTER DEFAULT PRIVILEGES FOR ROLE {owner} IN SCHEMA public GRANT SELECT, INSERT ON TABLES TO {rig};",
                  f"ALTER DEFAULT PRIVILEGES FOR ROLE {owner} IN SCHEMA public GRANT USAGE ON SEQUENCES TO {rig};"]
    return "\n".join(lines)
