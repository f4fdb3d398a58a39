"""`hopkinson config schema`: the JSON Schema an editor checks a file with says what the loader
does. Checked with an independent validator (jsonschema): every shipped file passes, and a file
the loader refuses for one key's type, range or name is refused by the schema too."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from hopkinson.rig.cli.main import main
from hopkinson.rig.config import load_rig_config, load_sim_config
from hopkinson.rig.config_schema import KINDS, schema_text
from hopkinson.rig.errors import ConfigError
from hopkinson.rig.plan import load_plan
from tests.rig.test_config import BAD_RIG, BAD_SIM

CONFIG = Path(__file__).resolve().parents[2] / "config"
SHIPPED = {"rig.toml": "rig", "rig-sim.toml": "rig", "sim.toml": "sim", "campaigns/demo.toml": "plan",
           "campaigns/example.toml": "plan", "campaigns/linearity.toml": "plan"}
LOADERS = {"rig": load_rig_config, "sim": load_sim_config, "plan": load_plan}


def _validator(kind: str) -> jsonschema.Draft202012Validator:
    schema = json.loads((CONFIG / "schemas" / f"{kind}.schema.json").read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


@pytest.mark.parametrize("kind", KINDS)
def test_the_shipped_schemas_are_the_declarations_of_today(kind: str) -> None:
    shipped = (CONFIG / "schemas" / f"{kind}.schema.json").read_text(encoding="utf-8")
    assert shipped == schema_text(kind), (
        f"config/schemas/{kind}.schema.json is out of date: run `hopkinson config schema --out config/schemas`")


@pytest.mark.parametrize(("name", "kind"), SHIPPED.items())
def test_every_shipped_file_points_at_its_schema_and_passes_it(name: str, kind: str) -> None:
    path = CONFIG / name
    first = path.read_text(encoding="utf-8").splitlines()[0]
    assert first.startswith("#:schema ") and (path.parent / first.split()[1]).resolve() == \
        (CONFIG / "schemas" / f"{kind}.schema.json").resolve()
    errors = [e.message for e in _validator(kind).iter_errors(tomllib.loads(path.read_text(encoding="utf-8")))]
    assert errors == []
    LOADERS[kind](path)


# The cases of test_config.py whose reason lies in one key's own declaration (type, range, name,
# choice, length) rather than in a check across keys; and three of a plan's.
PER_KEY = ("must be an integer", "must be at most", "must be at least", "must be greater than", "unknown",
           "must be one of", "must have", "must be true or false")
PLAN_CASES = [
    ("campaigns/example.toml", "projectile = 2 ", "projectile = 4 ", "shots[3].projectile"),
    ("campaigns/example.toml", "repeats = 2", "repeats = 0", "shots[3].repeats"),
    ("campaigns/example.toml", "dcm_damping = 0.707", "dcm_damping = 1.5", "defaults.analysis.dcm_damping"),
    ("campaigns/example.toml", 'dcm_ratio = "auto"', 'dcm_ratio = "manual"', "defaults.analysis.dcm_ratio"),
    ("campaigns/example.toml", 'serial = "SN0001"', 'serial = "SN0001"\ncolour = "red"', "accelerometer.colour"),
]
CASES = [(source, old, new, key) for source, cases in (("rig.toml", BAD_RIG), ("sim.toml", BAD_SIM))
         for old, new, key, reason in cases
         if reason.startswith(PER_KEY) and "serial bridge" not in reason
         # 2.5e5 is 250000.0: an integer to JSON Schema (a number's value, not its spelling), a float to TOML
         and new != "record_length = 2.5e5"] + PLAN_CASES


@pytest.mark.parametrize(("name", "old", "new", "key"), CASES)
def test_what_the_loader_refuses_for_a_key_the_schema_refuses(tmp_path: Path, name: str, old: str, new: str,
                                                              key: str) -> None:
    kind = SHIPPED[name]
    text = (CONFIG / name).read_text(encoding="utf-8")
    assert old in text, old
    path = tmp_path / Path(name).name
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(ConfigError) as caught:
        LOADERS[kind](path)
    assert str(caught.value).startswith(f"{path}: {key}: ")
    assert not _validator(kind).is_valid(tomllib.loads(path.read_text(encoding="utf-8")))


def test_the_command_writes_the_three_schemas_and_checks_a_file(tmp_path: Path, capsys) -> None:
    assert main(["config", "schema", "--out", str(tmp_path / "schemas"), "--json"]) == 0
    written = json.loads(capsys.readouterr().out)
    assert sorted(written) == sorted(KINDS)
    for kind, path in written.items():
        assert Path(path).read_text(encoding="utf-8") == schema_text(kind)
    assert main(["config", "check", str(CONFIG / "sim.toml"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out) == {"file": str(CONFIG / "sim.toml"), "kind": "sim", "ok": True}
    bad = tmp_path / "plan.toml"
    bad.write_text((CONFIG / "campaigns" / "demo.toml").read_text(encoding="utf-8").replace("repeats = 2",
                                                                                           "repeats = 0"))
    assert main(["config", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err == f"hopkinson: error: {bad}: shots[1].repeats: must be 1..10000 (got 0)\n"


def test_the_configuration_page_has_a_heading_for_every_section_of_a_rig_file() -> None:
    import dataclasses

    from hopkinson.rig.config import RigConfig

    page = (CONFIG.parent / "docs" / "configuration.md").read_text(encoding="utf-8")
    headings = [line for line in page.splitlines() if line.startswith("### ")]
    for section in (f.name for f in dataclasses.fields(RigConfig) if f.name != "path"):
        assert any(f"[{section}]" in heading for heading in headings), section
