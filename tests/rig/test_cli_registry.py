"""Every sub-command comes from its own module's register(), listed in COMMAND_MODULES."""

from __future__ import annotations

from hopkinson.rig.cli.main import COMMAND_MODULES, build_parser


def test_each_command_is_registered_by_its_own_module() -> None:
    assert "hopkinson.rig.cli.probe" in COMMAND_MODULES
    parser = build_parser()
    for command, module in (("probe", "probe"), ("status", "sim"), ("sim", "sim")):
        args = parser.parse_args([command])
        assert args.func.__module__ == f"hopkinson.rig.cli.{module}", command
