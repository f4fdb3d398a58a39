"""Every sub-command comes from its own module's register(), listed in COMMAND_MODULES."""

from __future__ import annotations

from hopkinson.rig.cli.main import COMMAND_MODULES, build_parser


def test_each_command_is_registered_by_its_own_module() -> None:
    assert "hopkinson.rig.cli.probe" in COMMAND_MODULES
    parser = build_parser()
    for command, module in (("probe", "probe"), ("status", "sim"), ("sim", "sim")):
        args = parser.parse_args([command])
        assert args.func.__module__ == f"hopkinson.rig.cli.{module}", command


def test_the_commands_without_json_are_the_ones_the_readme_names() -> None:
    # issue 18: the README said every command takes --json; these do not (they report no result)
    import argparse
    from pathlib import Path

    without: list[str] = []

    def walk(parser: argparse.ArgumentParser, words: list[str]) -> None:
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if subs:
            for name, sub in subs[0].choices.items():
                walk(sub, [*words, name])
        elif not any("--json" in a.option_strings for a in parser._actions):
            without.append(" ".join(words))

    walk(build_parser(), [])
    assert sorted(without) == ["campaign decide", "demo", "lab upgrade", "panel", "sim"]
    readme = (Path(__file__).resolve().parents[2] / "docs" / "commands.md").read_text(encoding="utf-8")
    assert "all but `demo`, `sim`, `panel`, `campaign decide` and `lab upgrade`" in readme


def test_lab_grants_json_is_one_object_holding_the_sql(capsys) -> None:
    import json

    from hopkinson.rig.cli.main import main

    assert main(["lab", "grants", "lab_rig", "--owner", "lab_owner", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["rig_role"] == "lab_rig" and out["owner"] == "lab_owner"
    assert "GRANT" in out["sql"].upper() and "lab_rig" in out["sql"]
