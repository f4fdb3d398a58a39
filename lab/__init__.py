"""The lab's record: every calibration in one database (docs/architecture.md, docs/decisions/0015).

`database` opens it (SQLite in the user's data folder by default, PostgreSQL for a lab) and
keeps its schema at the version this software knows (Alembic migrations in `migrations/`);
`repository` is the one layer that reads and writes it (sensors, rigs and reference chains,
campaigns, shots and their analyses, certificates, the append-only audit trail); `history`
judges a sensor's calibrations over time; `certificate` writes a numbered certificate.
Imports analysis and reports of the project, never rig or ui (the rig records into it).
"""
