"""JSON Schemas of the three configuration files, from the same declarations the loaders check
(rig/config.py, rig/config_sim.py, rig/plan.py): what `hopkinson config schema` writes, so an
editor (Taplo, VS Code's Even Better TOML) completes and checks a file as it is typed."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from hopkinson.rig.config_errors import schema

KINDS = {"rig": "a rig's configuration (config/rig.toml, config/rig-sim.toml)",
         "sim": "the simulated rig (config/sim.toml)",
         "plan": "a campaign plan (config/campaigns/*.toml)"}
DIALECT = "https://json-schema.org/draft/2020-12/schema"


def file_type(kind: str) -> type:
    """The dataclass a file of `kind` ("rig", "sim", "plan") is validated as."""
    if kind == "rig":
        from hopkinson.rig.config import RigConfig

        return RigConfig
    if kind == "sim":
        from hopkinson.rig.config_sim import SimFile

        return SimFile
    if kind == "plan":
        from hopkinson.rig.plan import PlanFile

        return PlanFile
    raise ValueError(f"no configuration kind {kind!r} (kinds: {', '.join(KINDS)})")


def kind_schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of a file of `kind`."""
    body = schema(file_type(kind))
    return {"$schema": DIALECT, "title": f"hopkinson {kind}.toml", **{k: v for k, v in body.items() if k != "title"},
            "description": f"hopkinson: {KINDS[kind]}. docs/configuration.md describes every key."}


def schema_text(kind: str) -> str:
    """The schema as the file `<kind>.schema.json` holds it (sorted keys, one trailing newline)."""
    return json.dumps(kind_schema(kind), indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def write_schemas(folder: Path) -> list[Path]:
    """`<kind>.schema.json` for every kind into `folder` (made if needed); the paths written."""
    from hopkinson.fileio import atomic_write

    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for kind in KINDS:
        written.append(atomic_write(folder / f"{kind}.schema.json", schema_text(kind)))
    return written
