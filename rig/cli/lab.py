"""`hopkinson lab`: the lab's record (hopkinson.lab) from the command line.

    hopkinson lab status                       where the record is, its schema, its rows, the spool
    hopkinson lab upgrade                      migrate the schema to this software's (first use creates it)
    hopkinson lab import RUN_FOLDER|SHOT.h5…   record shots measured before (idempotent), and the spool
    hopkinson lab sensor SERIAL [--json] [--plot FILE.png] [--model … --owner … --nominal-sensitivity …
                         --sensitivity-unit … --tolerance-percent … --interval-days …]
                                               a sensor's history: every calibration, drift (E_n),
                                               tolerance and due date; the options record its data
    hopkinson lab certificate RUN_FOLDER|CAMPAIGN -o cert.pdf|.html --authorised-by NAME
                         [--customer …] [--replaces NUMBER] [--specimen]
                                               issue a numbered certificate (<prefix>-<year>-<NNNN>);
                                               a campaign with simulated shots gets only a specimen
                                               (--specimen: <prefix>-SIM-<year>-<NNNN>, marked so)
    hopkinson lab audit [--subject S] [--json]  the audit trail, newest first

The database: --database, else HOPKINSON_DATABASE_URL, else the rig configuration's
[database] url, else SQLite in the user's data folder. The lab's name, certificate prefix,
decision rule and this rig's reference chain come from the configuration's [lab].
Exit codes: 0 done; 2 bad input, a database that cannot be reached or has another schema, a
tampered shot file (one line each, no traceback).
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
                       help="database URL (sqlite:///FILE or postgresql://…); else HOPKINSON_DATABASE_URL, else "
                            "the configuration's [database] url")
        p.set_defaults(func=func)
        return p

    command("status", "where the lab's record is, its schema version, its rows and the spool", status_command) \
        .add_argument("--json", action="store_true", help="one JSON object")
    command("upgrade", "migrate the database's schema to this software's version", upgrade_command)
    p = command("import", "record shot files measured before (idempotent), and any spooled records", import_command)
    p.add_argument("paths", nargs="+", type=Path, metavar="RUN_FOLDER|SHOT.h5")
    p.add_argument("--by", default="", help="who imports (default: the login name)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("sensor", "a sensor's calibration history: drift, tolerance, due date", sensor_command)
    p.add_argument("serial", metavar="SERIAL")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.add_argument("--plot", type=Path, metavar="FILE.png", help="also draw the history to a PNG")
    p.add_argument("--by", default="", help="who records the sensor's data (default: the login name)")
    p.add_argument("--model")
    p.add_argument("--owner", help="the sensor's owner (the certificate's customer by default)")
    p.add_argument("--nominal-sensitivity", type=float, metavar="VALUE")
    p.add_argument("--sensitivity-unit", metavar="UNIT", help="e.g. mV/g, pC/(m/s²)")
    p.add_argument("--tolerance-percent", type=float, metavar="PERCENT",
                   help="allowed deviation of the sensitivity from nominal (±%%)")
    p.add_argument("--interval-days", type=int, metavar="DAYS", help="calibration interval")
    p = command("certificate", "issue a numbered calibration certificate of a campaign", certificate_command)
    p.add_argument("source", metavar="RUN_FOLDER|CAMPAIGN", help="a run folder (imported first) or a campaign's name")
    p.add_argument("-o", "--output", type=Path, action="append", required=True, metavar="PATH",
                   help="certificate file, .pdf or .html (repeatable)")
    p.add_argument("--authorised-by", required=True, metavar="NAME", help="the person who authorises it")
    p.add_argument("--customer", default="", help="default: the sensor's owner")
    p.add_argument("--conditions", default="", metavar="TEXT",
                   help="environmental conditions of the calibration, e.g. '(23 ± 2) °C, (45 ± 10) %% r.h.'")
    p.add_argument("--replaces", default="", metavar="NUMBER", help="the certificate this one replaces")
    p.add_argument("--specimen", action="store_true",
                   help="a specimen, marked as simulated data on every page and numbered <prefix>-SIM-…: the "
                        "only document a campaign with simulated shots gets")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p = command("audit", "the audit trail, newest first", audit_command)
    p.add_argument("--subject", help="only entries about this shot UUID, certificate number or serial")
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


def _repository(args: argparse.Namespace, config: Any = None) -> Any:
    from hopkinson.lab.repository import open_repository

    config = config or _config(args)
    return open_repository(config.database.url, explicit=args.database)


def status_command(args: argparse.Namespace) -> int:
    from hopkinson.lab import spool
    from hopkinson.lab.database import current_revision, head_revision

    with _repository(args) as repo:
        out = {"database": repo.where, "schema": current_revision(repo.engine), "software_schema": head_revision(),
               "rows": repo.counts(), "spooled": len(spool.pending()), "spool": str(spool.spool_path())}
    if args.json:
        emit_json(out)
    else:
        for key, value in out.items():
            print(f"{key}: {value}")
    return 0


def upgrade_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.database import database_url, make_engine, redacted, upgrade_database

    config = _config(args)
    url = database_url(config.database.url, explicit=args.database)
    engine = make_engine(url)
    try:
        before, after = upgrade_database(engine)
    except Exception as exc:
        from hopkinson.lab.errors import LabError

        if isinstance(exc, LabError):
            raise
        raise LabError(f"database {redacted(url)}: {str(exc).splitlines()[0]}") from None
    finally:
        engine.dispose()
    print(f"database {redacted(url)}: schema {before or '(empty)'} -> {after}"
          + (" (already current)" if before == after else ""))
    return 0


def import_command(args: argparse.Namespace) -> int:
    import sys

    from hopkinson.rig.lab_record import import_shots

    refused, rows = 0, []
    with _repository(args) as repo:
        for path, outcome in import_shots(repo, args.paths, args.by or getpass.getuser()):
            rows.append({"path": str(path), "outcome": outcome})
            if outcome.startswith("refused: "):
                refused += 1
                sys.stderr.write(f"hopkinson: error: {outcome.removeprefix('refused: ')}\n")
            elif not args.json:
                print(f"{outcome}: {path}")
    if args.json:
        emit_json({"shots": rows, "refused": refused})
    return 2 if refused else 0


def sensor_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.errors import LabError
    from hopkinson.lab.history import sensor_history

    config = _config(args)
    fields = {"model": args.model, "owner": args.owner, "nominal_sensitivity": args.nominal_sensitivity,
              "sensitivity_unit": args.sensitivity_unit, "tolerance_percent": args.tolerance_percent,
              "interval_days": args.interval_days}
    for key in ("tolerance_percent", "interval_days", "nominal_sensitivity"):
        if fields[key] is not None and not fields[key] > 0:
            raise LabError(f"--{key.replace('_', '-')}: must be > 0, got {fields[key]}")
    with _repository(args, config) as repo:
        if any(v is not None for v in fields.values()):
            repo.register_sensor(args.serial, args.by or getpass.getuser(), **fields)
        sensor = repo.sensor(args.serial)
        if sensor is None:
            raise LabError(f"sensor {args.serial}: not in the lab's record")
        history = sensor_history(sensor, repo.calibrations(args.serial), config.lab.decision_rule)
        certificates = repo.certificates(args.serial)
    if args.plot is not None:
        from hopkinson.lab.history_plot import history_figure

        from hopkinson.fileio import atomic_write

        fig = history_figure(history)
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png", dpi=90))
    if args.json:
        emit_json(dict(history.to_dict(), certificates=certificates))
        return 0
    print(history_text(history, certificates))
    return 0


def history_text(history: Any, certificates: list[dict[str, str]]) -> str:
    """The history for people: the sensor, one line per calibration, drift and flags."""
    from hopkinson.lab.history_plot import SHOWN

    s = history.sensor
    lines = [f"sensor {s.serial}: {s.model or 'model unknown'}, owner {s.owner or '—'}, tolerance "
             f"{f'±{s.tolerance_percent:g} %' if s.tolerance_percent is not None else '—'}, interval "
             f"{f'{s.interval_days} days' if s.interval_days else '—'}",
             f"{len(history.calibrations)} calibration(s)" + (f"; due {history.due}" if history.due else "")]
    header = ["UTC", "rig", "campaign"] + [label for _key, label, _scale, _unit in SHOWN]
    lines.append("  ".join(header))
    for c in history.calibrations:
        cells = [c.utc_time[:19], c.rig, c.campaign or "—"]
        for key, _label, scale, unit in SHOWN:
            figure = c.figures.get(key)
            cells.append(figure.format(scale, unit=unit) if figure is not None else "—")
        lines.append("  ".join(cells))
    for key, d in history.drift.items():
        lines.append(f"drift {key}: E_n = {d.e_n:+.2f} ({'DRIFTED' if d.drifted else 'consistent'}; newest "
                     f"against {d.history_n} earlier)" if d.e_n is not None else f"drift {key}: no uncertainty")
    if history.conformity is not None:
        lines.append(history.conformity.statement())
    for c in certificates:
        lines.append(f"certificate {c['number']} issued {c['issued_utc'][:10]}"
                     + (f", replaces {c['replaces']}" if c["replaces"] else "") + f": {c['conformity']}")
    lines.append("flags: " + ("; ".join(history.flags) if history.flags else "none"))
    return "\n".join(lines)


def certificate_command(args: argparse.Namespace) -> int:
    from hopkinson.lab.certificate import (
        LabIdentity,
        certificate_content,
        with_number,
        write_certificate,
    )
    from hopkinson.lab.errors import LabError
    from hopkinson.rig.lab_record import import_shots
    from hopkinson.rig.shotfile import software_version

    from hopkinson.fileio import check_output_path

    for out in args.output:
        if out.suffix.lower() not in (".pdf", ".html"):
            raise LabError(f"-o {out}: a certificate is .pdf or .html")
        if not out.parent.is_dir():
            raise LabError(f"-o {out}: folder {out.parent} does not exist")
        check_output_path(out, [], what="certificate")
    config = _config(args)
    lab = config.lab
    identity = LabIdentity(lab.name, lab.address, lab.accreditation, lab.certificate_prefix, lab.decision_rule)
    source = Path(args.source)
    with _repository(args, config) as repo:
        if source.is_dir():
            refused = [o for _p, o in import_shots(repo, [source], getpass.getuser()) if o.startswith("refused")]
            if refused:
                raise LabError(refused[0].removeprefix("refused: "))
            campaign = source.resolve().name
        else:
            campaign = args.source
        content = certificate_content(repo, campaign, identity, customer=args.customer, conditions=args.conditions,
                                      authorised_by=args.authorised_by, software_version=software_version(),
                                      specimen=args.specimen)
        prefix = f"{identity.certificate_prefix}-SIM" if args.specimen else identity.certificate_prefix
        issued = repo.issue_certificate(
            prefix, content, serial=content["serial"], subject=campaign,
            authorised_by=args.authorised_by, replaces=args.replaces,
            number_into=lambda c, number, utc: with_number(c, number, utc, args.replaces))
    written = [str(write_certificate(issued.content, out)) for out in args.output]
    if args.json:
        emit_json({"number": issued.number, "replaces": issued.replaces or None, "files": written,
                   "conformity": issued.content["conformity"]})
    else:
        print(("specimen " if args.specimen else "") + f"certificate {issued.number}"
              + (f" (replaces {issued.replaces})" if issued.replaces else ""))
        for path in written:
            print(f"written: {path}")
    return 0


def audit_command(args: argparse.Namespace) -> int:
    with _repository(args) as repo:
        entries = repo.audit_trail(args.subject, limit=args.limit)
    if args.json:
        emit_json({"audit": entries})
    else:
        for a in entries:
            print(f"{a['utc']}  {a['actor']}  {a['action']}  {a['subject']}")
    return 0
