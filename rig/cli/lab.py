"""`hopkinson lab`: the lab's record (hopkinson.lab) from the command line.

    hopkinson lab status                       where the record is, its schema, its rows, the spool
                                               and the quarantine
    hopkinson lab upgrade [--yes-i-have-a-backup]
                                               migrate the schema (as the database's owner role):
                                               a SQLite file is copied beside itself first; on
                                               PostgreSQL, pg_dump first (the command is printed)
    hopkinson lab import [RUN_FOLDER|SHOT.h5…] record shots measured before (idempotent); with no
                                               path: the spool (this database's records, and those
                                               spooled before records named their database)
    hopkinson lab sensor SERIAL [--json] [--plot FILE.png] [--include-simulated] [--new]
                         [--model … --owner … --nominal-sensitivity … --sensitivity-unit …
                          --tolerance-percent … --interval-days …]
                                               a sensor's calibrations (campaigns): drift (E_n at
                                               like levels), tolerance, due date; the options
                                               record its data (--new: a serial no shot named yet)
    hopkinson lab job CAMPAIGN --received DATE --condition … --location … [--customer …
                         --customer-contact … --mounting … --environment …]
                                               a campaign's job record (ISO/IEC 17025 §7.8.2.1)
    hopkinson lab certificate RUN_FOLDER|CAMPAIGN -o cert.pdf [-o cert.xml] [-o cert.html]
                         --authorised-by NAME [--customer …] [--replaces NUMBER] [--specimen]
                         [--deviation TEXT]
                                               issue a numbered certificate and its documents (the
                                               DCC as .xml); the number exists only once they are
                                               written; simulated shots get only a specimen
    hopkinson lab reprint NUMBER -o FILE…      an issued certificate's documents again, from its
                                               stored content
    hopkinson lab verify [--json]              re-check every certificate's stored hash and every
                                               analysis against its shot file
    hopkinson lab grants RIG_ROLE [--owner ROLE] the SQL a DBA runs for the rig's role (PostgreSQL)
    hopkinson lab audit [--subject S] [--json]  the audit trail, newest first

The database: --database, else HOPKINSON_DATABASE_URL, else the rig configuration's
[database] url, else SQLite in the user's data folder. The lab's name, certificate prefix,
country, decision rule, signatories and this rig's reference chain come from the
configuration's [lab] (docs/lab-record.md).
Exit codes: 0 done; 1 `lab verify` found a discrepancy; 2 bad input, a database that cannot be
reached or has another schema, a tampered shot file (one line each, no traceback).
"""

from __future__ import annotations

import argparse
import getpass
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import DEFAULT_RIG_CONFIG, emit_json


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add `lab` and its sub-commands."""
    lab = subparsers.add_parser("lab", help="the lab's record: import, sensor history, certificates, audit",
                                description="The lab's record: every calibration in one database.")
    sub = lab.add_subparsers(dest="lab_command", metavar="LAB_COMMAND", required=True)

    def command(name: str, helptext: str, func: Any) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=helptext, description=helptext)
        func = _one_line_database_errors(func)
        p.add_argument("--config", type=Path, default=DEFAULT_RIG_CONFIG,
                       help="rig TOML with [lab] and [database] (default %(default)s)")
        p.add_argument("--database", default="", metavar="URL",
                       help="database URL (sqlite:////ABSOLUTE/FILE or postgresql://…); else HOPKINSON_DATABASE_URL, "
                            "else the configuration's [database] url")
        p.set_defaults(func=func)
        return p

    command("status", "where the lab's record is, its schema version, its rows, the spool and the quarantine",
            status_command).add_argument("--json", action="store_true", help="one JSON object")
    p = command("upgrade", "migrate the database's schema to this software's version (a SQLite file is copied beside "
                           "itself first; PostgreSQL asks for a pg_dump first)", upgrade_command)
    p.add_argument("--yes-i-have-a-backup", action="store_true",
                   help="PostgreSQL: the database was backed up with pg_dump (without this, the command only prints "
                        "the pg_dump to run)")
    p = command("import", "record shot files measured before (idempotent); with no path, the spool", import_command)
    p.add_argument("paths", nargs="*", type=Path, metavar="RUN_FOLDER|SHOT.h5")
    p.add_argument("--by", default="", help="who imports (default: the login name)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("sensor", "a sensor's calibration history: drift, tolerance, due date", sensor_command)
    p.add_argument("serial", metavar="SERIAL")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.add_argument("--plot", type=Path, metavar="FILE.png", help="also draw the history to a PNG")
    p.add_argument("--include-simulated", action="store_true",
                   help="judge simulated calibrations too (they are shown, marked, and left out by default)")
    p.add_argument("--new", action="store_true", help="record a sensor no shot has named yet")
    p.add_argument("--by", default="", help="who records the sensor's data (default: the login name)")
    p.add_argument("--model")
    p.add_argument("--owner", help="the sensor's owner (the certificate's customer by default)")
    p.add_argument("--nominal-sensitivity", type=float, metavar="VALUE")
    p.add_argument("--sensitivity-unit", metavar="UNIT", help="e.g. mV/g, pC/(m/s²)")
    p.add_argument("--tolerance-percent", type=float, metavar="PERCENT",
                   help="allowed deviation of the sensitivity from nominal (±%%)")
    p.add_argument("--interval-days", type=int, metavar="DAYS", help="calibration interval")
    p = command("job", "a campaign's job record: receipt, condition, location", job_command)
    p.add_argument("campaign", metavar="RUN_FOLDER|CAMPAIGN")
    p.add_argument("--received", metavar="YYYY-MM-DD", help="date the item was received")
    p.add_argument("--condition", help="condition of the item as received")
    p.add_argument("--location", help="where the calibration was done")
    p.add_argument("--customer")
    p.add_argument("--customer-contact", metavar="TEXT")
    p.add_argument("--mounting", help="how the accelerometer was mounted (torque, adapter, couplant)")
    p.add_argument("--environment", help="e.g. '(23 ± 2) °C, (45 ± 10) %% r.h.'")
    p.add_argument("--by", default="", help="who records it (default: the login name)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("certificate", "issue a numbered calibration certificate of a campaign", certificate_command)
    p.add_argument("source", metavar="RUN_FOLDER|CAMPAIGN", help="a run folder (imported first), or a campaign's "
                                                                 "UUID or unambiguous name")
    p.add_argument("-o", "--output", type=Path, action="append", required=True, metavar="PATH",
                   help="a document: .pdf, .html, or .xml (PTB's Digital Calibration Certificate); repeatable")
    p.add_argument("--authorised-by", required=True, metavar="NAME", help="an authorised signatory ([[lab.signatories]])")
    p.add_argument("--customer", default="", help="default: the job record's, else the sensor's owner")
    p.add_argument("--conditions", default="", metavar="TEXT",
                   help="environmental conditions, e.g. '(23 ± 2) °C, (45 ± 10) %% r.h.' (default: the job record's)")
    p.add_argument("--deviation", action="append", default=[], metavar="TEXT",
                   help="a deviation from the method to state (repeatable; those beyond the standard's scope are "
                        "stated by themselves)")
    p.add_argument("--replaces", default="", metavar="NUMBER", help="the valid certificate this one replaces")
    p.add_argument("--specimen", action="store_true",
                   help="a specimen, marked as simulated data on every page and numbered <prefix>-SIM-…: the "
                        "only document a campaign with simulated shots gets")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("reprint", "an issued certificate's documents again, from its stored content", reprint_command)
    p.add_argument("number", metavar="NUMBER")
    p.add_argument("-o", "--output", type=Path, action="append", required=True, metavar="PATH")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("verify", "re-check every certificate's hash and every analysis against its shot file", verify_command)
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("grants", "the SQL that gives the rig's role INSERT and SELECT only (PostgreSQL)", grants_command)
    p.add_argument("rig_role", metavar="RIG_ROLE")
    p.add_argument("--owner", default="", metavar="ROLE", help="the role that owns the tables and runs `lab upgrade`")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("audit", "the audit trail, newest first", audit_command)
    p.add_argument("--subject", help="only entries about this shot UUID, certificate number, campaign UUID or serial")
    p.add_argument("--limit", type=int, default=50)
    p.add_argument("--json", action="store_true", help="one JSON object")


def _one_line_database_errors(func: Any) -> Any:
    """A database error anywhere in a command becomes one line (LabError: exit 2), never a traceback."""
    def run(args: argparse.Namespace) -> int:
        import sqlalchemy as sa

        from hopkinson.lab.database import first_line
        from hopkinson.lab.errors import LabError

        try:
            return func(args)
        except sa.exc.SQLAlchemyError as exc:
            raise LabError(f"database: {first_line(exc)}") from None

    return run


def _config(args: argparse.Namespace) -> Any:
    from hopkinson.rig.config import load_rig_config

    return load_rig_config(args.config)


def _repository(args: argparse.Namespace, config: Any = None, create: bool = True) -> Any:
    from hopkinson.lab.repository import open_repository

    config = config or _config(args)
    return open_repository(config.database.url, explicit=args.database, create=create)


def status_command(args: argparse.Namespace) -> int:
    from hopkinson.lab import spool
    from hopkinson.lab.database import current_revision, head_revision

    with _repository(args, create=False) as repo:
        out = {"database": repo.where, "schema": current_revision(repo.engine), "software_schema": head_revision(),
               "rows": repo.counts(), "spooled": spool.waiting_records(repo.where),
               "spooled_for_other_databases": spool.waiting_records() - spool.waiting_records(repo.where),
               "spool": str(spool.spool_path()),
               "quarantined": [{"shot": q.record.uuid, "path": q.record.path, "database": q.database,
                                "reason": q.reason, "utc": q.utc} for q in spool.quarantined()],
               "quarantine": str(spool.quarantine_path())}
    if args.json:
        emit_json(out)
    else:
        for key, value in out.items():
            if key == "quarantined":
                print(f"quarantined: {len(value)}")
                for q in value:
                    print(f"  {q['path']}: {q['reason']}")
            else:
                print(f"{key}: {value}")
    return 0


def upgrade_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.database import database_url, redacted
    from hopkinson.lab.upgrade import upgrade_record

    config = _config(args)
    url = database_url(config.database.url, explicit=args.database)
    outcome = upgrade_record(url, have_backup=args.yes_i_have_a_backup)
    print(f"database {redacted(url)}: schema {outcome.before or '(empty)'} -> {outcome.after}"
          + (" (already current)" if outcome.before == outcome.after else ""))
    if outcome.backup is not None:
        print(f"backup taken before: {outcome.backup}")
    for note in outcome.notes:
        print(note)
    if outcome.dialect == "postgresql" and outcome.before != outcome.after:
        print("run `hopkinson lab grants RIG_ROLE --owner OWNER_ROLE` again for the new tables (docs/lab-record.md)")
    return 0


def import_command(args: argparse.Namespace) -> int:
    import sys

    from hopkinson.rig.lab_record import import_shots

    refused, rows = 0, []
    with _repository(args) as repo:
        for path, outcome in import_shots(repo, args.paths, args.by or getpass.getuser(), legacy_spool=not args.paths):
            rows.append({"path": str(path), "outcome": outcome})
            if outcome.startswith("refused: "):
                refused += 1
                sys.stderr.write(f"hopkinson: error: {outcome.removeprefix('refused: ')}\n")
            elif not args.json:
                print(f"{outcome}: {path}")
    if not rows and not args.json:
        print("nothing to import: the spool holds nothing for this database")
    if args.json:
        emit_json({"shots": [r for r in rows if r["path"] != "spool"], "refused": refused,
                   "spool": next((r["outcome"] for r in rows if r["path"] == "spool"), "")})
    return 2 if refused else 0


def sensor_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.errors import LabError
    from hopkinson.lab.history import load_sensor_history

    config = _config(args)
    fields = {"model": args.model, "owner": args.owner, "nominal_sensitivity": args.nominal_sensitivity,
              "sensitivity_unit": args.sensitivity_unit, "tolerance_percent": args.tolerance_percent,
              "interval_days": args.interval_days}
    for key in ("tolerance_percent", "interval_days", "nominal_sensitivity"):
        if fields[key] is not None and not fields[key] > 0:
            raise LabError(f"--{key.replace('_', '-')}: must be > 0, got {fields[key]}")
    changing = any(v is not None for v in fields.values()) or args.new
    with _repository(args, config, create=changing) as repo:
        if changing:
            repo.register_sensor(args.serial, args.by or getpass.getuser(), create=args.new, **fields)
        history = load_sensor_history(repo, args.serial, config.lab.decision_rule, args.include_simulated)
    if args.plot is not None:
        from hopkinson.fileio import atomic_write
        from hopkinson.lab.history_plot import history_figure

        fig = history_figure(history)
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png", dpi=90))
    if args.json:
        emit_json(history.to_dict())
        return 0
    print(history_text(history))
    return 0


def history_text(history: Any) -> str:
    """The history for people: the sensor, one line per calibration (simulated ones marked),
    drift and flags."""
    from hopkinson.lab.history_plot import SHOWN

    s = history.sensor
    lines = [f"sensor {s.serial}: {s.model or 'model unknown'}, owner {s.owner or '—'}, tolerance "
             f"{f'±{s.tolerance_percent:g} %' if s.tolerance_percent is not None else '—'}, interval "
             f"{f'{s.interval_days} days' if s.interval_days else '—'}",
             f"{len(history.calibrations)} calibration(s)" + (f"; due {history.due} (UTC)" if history.due else "")]
    header = ["last shot (UTC)", "rig", "campaign", "shots", "stated sensitivity"] + [
        label for key, label, _scale, _unit in SHOWN if key != "sensitivity"]
    lines.append("  ".join(header))
    for c in history.calibrations:
        absolute = c.absolute.format(unit=c.absolute_unit) if c.absolute is not None else \
            (c.figures["sensitivity"].format() if c.figures.get("sensitivity") else "—")
        cells = [c.utc_time[:19] + "Z", c.rig, c.campaign or "—", str(len(c.shots)), absolute]
        for key, _label, scale, unit in SHOWN:
            if key != "sensitivity":
                figure = c.figures.get(key)
                cells.append(figure.format(scale, unit=unit) if figure is not None else "—")
        lines.append("  ".join(cells) + ("  SIMULATED" if c.simulated else ""))
    for key, d in history.drift.items():
        lines.append(f"drift {key}: E_n = {d.e_n:+.2f} ({'DRIFTED' if d.drifted else 'consistent'}; newest against "
                     f"the previous calibration at {d.levels} like level(s))" if d.e_n is not None
                     else f"drift {key}: no uncertainty")
    if history.conformity is not None:
        lines.append(history.conformity.statement())
    for c in history.certificates:
        lines.append(f"certificate {c['number']} issued {c['issued_utc'][:10]} (UTC)"
                     + (f", replaces {c['replaces']}" if c["replaces"] else "")
                     + (f", withdrawn (replaced by {c['withdrawn_by']})" if c["withdrawn_by"] else "")
                     + f": {c['conformity']}")
    lines.append("flags: " + ("; ".join(history.flags) if history.flags else "none"))
    return "\n".join(lines)


def _campaign_ref(repo: Any, source: str, actor: str) -> str:
    from hopkinson.rig.lab_record import campaign_ref

    return campaign_ref(repo, source, actor)


def job_command(args: argparse.Namespace) -> int:
    from datetime import date

    from hopkinson.lab.errors import LabError

    if args.received:
        try:
            date.fromisoformat(args.received)
        except ValueError:
            raise LabError(f"--received: a date YYYY-MM-DD, got {args.received!r}") from None
    fields = {k: getattr(args, k) for k in ("received", "condition", "location", "customer", "customer_contact",
                                            "mounting", "environment")}
    if all(v is None for v in fields.values()):
        raise LabError("lab job: nothing to record (--received, --condition, --location, …)")
    actor = args.by or getpass.getuser()
    with _repository(args) as repo:
        ref = _campaign_ref(repo, args.campaign, actor)
        job = repo.transact(actor, lambda uow: _job_dict(uow.campaigns.record_job(uow.campaigns.find(ref), **fields)))
    if args.json:
        emit_json({"campaign": str(ref), "job": job})
        return 0
    print(f"job recorded for campaign {ref}: " + ", ".join(f"{k} {v!r}" for k, v in job.items() if v))
    return 0


def _job_dict(job: Any) -> dict[str, str]:
    return {k: getattr(job, k) for k in ("received", "condition", "location", "customer", "customer_contact",
                                         "mounting", "environment")}


def _identity(config: Any) -> Any:
    from hopkinson.rig.lab_record import lab_identity

    return lab_identity(config)


def _check_documents(outputs: list[Path]) -> None:
    from hopkinson.fileio import check_output_path
    from hopkinson.lab.certificate import DOCUMENT_SUFFIXES
    from hopkinson.lab.errors import LabError

    for out in outputs:
        if out.suffix.lower() not in DOCUMENT_SUFFIXES:
            raise LabError(f"-o {out}: a certificate is written as {', '.join(DOCUMENT_SUFFIXES)}")
        if not out.parent.is_dir():
            raise LabError(f"-o {out}: folder {out.parent} does not exist")
        check_output_path(out, [], what="certificate")


def certificate_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.certificate import Request, certificate_content, write_documents
    from hopkinson.lab.issuing import issue
    from hopkinson.rig.shotfile import software_version

    _check_documents(args.output)
    config = _config(args)
    identity = _identity(config)
    identity.role_of(args.authorised_by, args.specimen)  # refused before anything is imported
    request = Request(args.authorised_by, software_version(), args.customer, args.conditions, tuple(args.deviation),
                      args.specimen)
    with _repository(args, config) as repo:
        ref = _campaign_ref(repo, args.source, getpass.getuser())
        issued = issue(repo, campaign=ref, prefix=identity.certificate_prefix, authorised_by=args.authorised_by,
                       specimen=args.specimen, replaces=args.replaces,
                       content=lambda uow, campaign: certificate_content(uow, campaign, identity, request),
                       documents=lambda content: write_documents(content, list(args.output), identity))
    written = [str(p) for p in args.output]
    if args.json:
        emit_json({"number": issued.number, "replaces": issued.replaces or None, "files": written,
                   "conformity": issued.content["conformity"], "campaign_uuid": issued.content["campaign_uuid"]})
    else:
        print(("specimen " if args.specimen else "") + f"certificate {issued.number}"
              + (f" (replaces {issued.replaces}, now withdrawn)" if issued.replaces else ""))
        for path in written:
            print(f"written: {path}")
    return 0


def reprint_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.certificate import write_documents
    from hopkinson.lab.errors import LabError

    _check_documents(args.output)
    config = _config(args)
    with _repository(args, config, create=False) as repo:
        issued = repo.certificate(args.number)
    if issued is None:
        raise LabError(f"certificate {args.number}: not in the lab's record")
    written = write_documents(issued.content, list(args.output), _identity(config))
    if args.json:
        emit_json({"number": args.number, "written": [str(p) for p in written],
                   "withdrawn_by": issued.withdrawn_by or None})
        return 0
    for path in written:
        print(f"written: {path}" + (f" (withdrawn: replaced by {issued.withdrawn_by})" if issued.withdrawn_by else ""))
    return 0


def verify_command(args: argparse.Namespace) -> int:
    from hopkinson.rig.lab_record import verify_record

    with _repository(args, create=False) as repo:
        report = verify_record(repo)
    if args.json:
        emit_json(report)
    else:
        print(f"certificates: {report['certificates']} checked; shots: {report['shots']} checked, "
              f"{len(report['missing_files'])} file(s) not found")
        for line in report["problems"]:
            print(f"PROBLEM: {line}")
        for path in report["missing_files"]:
            print(f"not found: {path}")
        print("verified: no discrepancy" if not report["problems"] else f"{len(report['problems'])} discrepancies")
    return 1 if report["problems"] else 0


def grants_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.roles import grants_sql

    sql = grants_sql(args.rig_role, args.owner)
    if args.json:
        emit_json({"rig_role": args.rig_role, "owner": args.owner or None, "sql": sql})
    else:
        print(sql)
    return 0


def audit_command(args: argparse.Namespace) -> int:
    with _repository(args, create=False) as repo:
        entries = repo.audit_trail(args.subject, limit=args.limit)
    if args.json:
        emit_json({"audit": entries})
    else:
        for a in entries:
            print(f"{a['utc']}  {a['actor']}  {a['action']}  {a['subject']}")
    return 0
