"""`hopkinson config`: the configuration files' JSON Schemas, and a file checked on its own.

    hopkinson config schema [--out DIR] [--json]
    hopkinson config check FILE [--kind rig|sim|plan] [--json]

`schema` writes rig.schema.json, sim.schema.json and plan.schema.json into DIR (default: the
current folder) from the declarations the loaders check: point an editor at them (a first
line ``#:schema ./rig.schema.json`` in the TOML file; docs/configuration.md). `check` loads a
file as the commands would (rig, sim or plan: guessed from its tables unless --kind says) and
prints "ok" or the one-line error (exit 2).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from hopkinson.rig.cli.main import emit_json

KINDS = ("rig", "sim", "plan")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("config", help="configuration files: JSON Schemas, check a file",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="config_command", metavar="ACTION", required=True)
    schema = sub.add_parser("schema", help="write the JSON Schema of each file kind (rig, sim, plan)")
    schema.add_argument("--out", type=Path, default=Path("."), help="folder to write into (default: here)")
    schema.add_argument("--json", action="store_true", help="print {kind: path written} as JSON")
    schema.set_defaults(func=run_schema)
    check = sub.add_parser("check", help="load a rig, sim or plan file and report the first problem")
    check.add_argument("file", type=Path)
    check.add_argument("--kind", choices=KINDS, help="the file's kind (default: guessed from its tables)")
    check.add_argument("--json", action="store_true", help="print {file, kind, ok} as JSON")
    check.set_defaults(func=run_check)


def run_schema(args: argparse.Namespace) -> int:
    from hopkinson.rig.config_schema import write_schemas

    written = write_schemas(args.out)
    if args.json:
        emit_json({path.name.split(".")[0]: str(path) for path in written})
    else:
        for path in written:
            print(f"wrote {path}")
    return 0


def run_check(args: argparse.Namespace) -> int:
    from hopkinson.rig.toml_file import read_toml

    kind = args.kind or guess_kind(read_toml(args.file)[0])
    if kind == "rig":
        from hopkinson.rig.config import load_rig_config

        load_rig_config(args.file)
    elif kind == "sim":
        from hopkinson.rig.config import load_sim_config

        load_sim_config(args.file)
    else:
        from hopkinson.rig.plan import load_plan

        load_plan(args.file)
    if args.json:
        emit_json({"file": str(args.file), "kind": kind, "ok": True})
    else:
        print(f"{args.file}: ok ({kind})")
    return 0


def guess_kind(document: dict[str, Any]) -> str:
    """"plan" (it has shots), "sim" (servers, world or register_map) or "rig"."""
    if "shots" in document:
        return "plan"
    if {"servers", "world", "register_map"} & set(document):
        return "sim"
    return "rig"
