"""Every sub-command comes from its own module's register(), listed in COMMAND_MODULES."""

from __future__ import annotations

import argparse
import importlib

import pytest

from hopkinson.rig.cli.main import COMMAND_MODULES, build_parser, command_module


def test_each_command_is_registered_by_its_own_module() -> None:
    assert "hopkinson.rig.cli.probe" in COMMAND_MODULES
    parser = build_parser()
    for command, module in (("probe", "probe"), ("status", "sim"), ("sim", "sim")):
        args = parser.parse_args([command])
        assert args.func.__module__ == f"hopkinson.rig.cli.{module}", command


def commands_of(parser: argparse.ArgumentParser) -> list[str]:
    return list(next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices)


def test_a_named_command_builds_only_the_parser_of_the_module_that_registers_it() -> None:
    """`hopkinson identify ...` registers identify's module alone (its start-up); every command
    the full parser knows is found in its own module's, and nowhere else."""
    everything = commands_of(build_parser())
    registered_by: dict[str, str] = {}
    for name in COMMAND_MODULES:
        sub = argparse.ArgumentParser().add_subparsers()
        importlib.import_module(name).register(sub)
        registered_by.update(dict.fromkeys(sub.choices, name))
    assert sorted(registered_by) == sorted(everything)
    for command in everything:
        assert command_module(command) == registered_by[command], command
        alone = commands_of(build_parser(command))
        assert command in alone
        assert {registered_by[c] for c in alone} == {registered_by[command]}, (command, alone)
    for unknown in (None, "no-such-command", "../identify", "Identify"):
        assert command_module(unknown) is None
        assert commands_of(build_parser(unknown)) == everything


@pytest.mark.parametrize("words", [["identify", "r.csv", "--max-order", "7"], ["status", "--sim"],
                                   ["compensate", "--help"], ["lab", "--help"], ["plan-shot", "--help"],
                                   ["identify", "--no-such-option"], ["lab", "no-such-subcommand"]])
def test_a_command_line_parses_and_reads_the_same_with_the_one_module_as_with_all(words, capsys) -> None:
    def outcome(parser: argparse.ArgumentParser) -> tuple[object, str, str]:
        try:
            args = vars(parser.parse_args(words))
            args = {k: (v.__qualname__ if callable(v) else v) for k, v in args.items()}
        except SystemExit as stop:
            args = stop.code
        out = capsys.readouterr()
        return args, out.out, out.err

    named = next((w for w in words if not w.startswith("-")), None)
    assert outcome(build_parser(named)) == outcome(build_parser())


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
