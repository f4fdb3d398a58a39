"""`hopkinson sim` (run the simulated rig) and `hopkinson status` (ask every instrument).

    hopkinson sim [--config config/sim.toml] [--fault NAME ...] [--addresses-json PATH]
    hopkinson sim --list-faults
    hopkinson status [--config config/rig.toml] [--json]

`sim` prints the three addresses (Modbus host:port, VISA resource, serial device) and runs
until Ctrl-C or SIGTERM, then stops its servers and exits 0. `status` connects to each
instrument in turn and reports identity, pressures, vacuum, valves, interlocks and the
amplifier's state; an instrument that cannot be reached is reported with the reason and the
others are still asked. Exit code 0 when every instrument answered, 1 when one did not,
2 for a bad configuration.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.rig.cli.main import DEFAULT_RIG_CONFIG, DEFAULT_SIM_CONFIG, emit_json, fail

if TYPE_CHECKING:
    from hopkinson.drivers.amplifier import BridgeAmplifier
    from hopkinson.drivers.digitizer import Digitizer
    from hopkinson.drivers.valve_controller import ValveController
    from hopkinson.rig.config import RigConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `sim` and `status` sub-commands."""
    sim = subparsers.add_parser(
        "sim", help="run the simulated rig (Modbus, VISA socket, serial pty) until Ctrl-C",
        description="Run the simulated rig: valve/vacuum controller (Modbus TCP), digitizer "
                    "(SCPI socket) and bridge amplifier (serial pty), driven by one physics model.")
    sim.add_argument("--config", type=Path, default=DEFAULT_SIM_CONFIG, help="simulator TOML (default %(default)s)")
    sim.add_argument("--fault", action="append", default=[], metavar="NAME",
                     help="inject a named fault (repeatable; see --list-faults)")
    sim.add_argument("--addresses-json", type=Path, metavar="PATH", help="also write the addresses as JSON here")
    sim.add_argument("--list-faults", action="store_true", help="list the fault names, one line each, and exit")
    sim.set_defaults(func=run_sim)

    status = subparsers.add_parser(
        "status", help="connect to every instrument and report identity, pressures, vacuum, interlocks",
        description="Connect to each instrument of the rig configuration and report its state.")
    status.add_argument("--config", type=Path, default=DEFAULT_RIG_CONFIG, help="rig TOML (default %(default)s)")
    status.add_argument("--json", action="store_true", help="one JSON object on stdout")
    status.set_defaults(func=run_status)


# -- sim ------------------------------------------------------------------------------------------
def run_sim(args: argparse.Namespace) -> int:
    from hopkinson.drivers.sim.faults import FAULTS
    from hopkinson.drivers.sim.simulated_rig import fault_list_text, run_simulator
    from hopkinson.rig.config import load_sim_config

    if args.list_faults:
        print(fault_list_text())
        return 0
    unknown = [name for name in args.fault if name not in FAULTS]
    if unknown:
        return fail(f"unknown fault {unknown[0]!r}; known: {', '.join(FAULTS)}")
    config = load_sim_config(args.config)
    try:
        return run_simulator(config, args.fault, args.addresses_json)
    except (OSError, RuntimeError) as exc:
        return fail(f"cannot start the simulated rig ({args.config}): {exc}")


# -- status ---------------------------------------------------------------------------------------
def run_status(args: argparse.Namespace) -> int:
    from hopkinson.rig.config import load_rig_config

    config = load_rig_config(args.config)
    report = rig_status(config)
    if args.json:
        emit_json(report)
    else:
        print(format_status(report))
    return 0 if report["ok"] else 1


def rig_status(config: RigConfig) -> dict[str, Any]:
    """Ask every instrument; a failure is recorded under its name, never raised."""
    from hopkinson.rig.instruments import make_instruments

    instruments = make_instruments(config)
    report: dict[str, Any] = {"config": config.path}
    report["valve_controller"] = _ask(f"{config.valve_controller.host}:{config.valve_controller.port}",
                                      lambda: _valve_controller_status(instruments.valves))
    report["digitizer"] = _ask(config.digitizer.resource, lambda: _digitizer_status(instruments.digitizer))
    report["amplifier"] = _ask(config.amplifier.port, lambda: _amplifier_status(instruments.amplifier))
    report["ok"] = all(report[k]["ok"] for k in ("valve_controller", "digitizer", "amplifier"))
    return report


def _ask(address: str, query: Any) -> dict[str, Any]:
    from hopkinson.drivers.errors import InstrumentError

    try:
        return {"address": address, "ok": True, **query()}
    except (InstrumentError, OSError, ValueError) as exc:
        return {"address": address, "ok": False, "error": str(exc)}


def _valve_controller_status(vc: ValveController) -> dict[str, Any]:
    from hopkinson.drivers.errors import InstrumentError

    with vc:
        try:
            identity = vc.identity()
        except InstrumentError as exc:  # identification is optional in Modbus: report, go on
            identity = f"(no identification: {exc.problem})"
        status = vc.status()
    return {
        "identity": identity,
        "reservoir_pressure_bar": status.reservoir_pressure_bar,
        "pressure_setpoint_bar": status.pressure_setpoint_bar,
        "fixture_vacuum_mbar": status.fixture_vacuum_mbar,
        "valves": asdict(status.valves),
        "interlocks": asdict(status.interlocks),
        "interlock_problems": status.interlocks.problems(),
    }


def _digitizer_status(dig: Digitizer) -> dict[str, Any]:
    with dig:
        return {
            "identity": dig.identity(),
            "state": dig.acquisition_state(),
            "sample_rate_hz": dig.sample_rate_hz(),
            "record_length": dig.record_length(),
        }


def _amplifier_status(amp: BridgeAmplifier) -> dict[str, Any]:
    with amp:
        return asdict(amp.status())


def format_status(report: dict[str, Any]) -> str:
    """The status report as lines for a person."""
    lines = [f"config: {report['config']}"]
    titles = {"valve_controller": "valve/vacuum controller", "digitizer": "digitizer", "amplifier": "bridge amplifier"}
    for key, title in titles.items():
        entry = report[key]
        if not entry["ok"]:
            lines.append(f"{title} ({entry['address']}): NOT REACHABLE: {entry['error']}")
            continue
        lines.append(f"{title} ({entry['address']}): {entry['identity']}")
        if key == "valve_controller":
            v = entry["valves"]
            valves = (f"fire {'open' if v['fire_valve'] else 'shut'}, fill {'open' if v['fill_valve'] else 'shut'}, "
                      f"vent {'open' if v['vent_valve'] else 'shut'}, pump {'on' if v['vacuum_pump'] else 'off'}")
            problems = ", ".join(entry["interlock_problems"]) or "all safe"
            lines += [
                f"  reservoir pressure {entry['reservoir_pressure_bar']:.3f} bar "
                f"(set-point {entry['pressure_setpoint_bar']:.3f} bar)",
                f"  fixture vacuum     {entry['fixture_vacuum_mbar']:.1f} mbar",
                f"  valves             {valves}",
                f"  interlocks         {problems}",
            ]
        elif key == "digitizer":
            lines.append(f"  state {entry['state']}, {entry['sample_rate_hz'] / 1e6:g} MS/s, "
                         f"{entry['record_length']} samples")
        else:
            lowpass = "off" if entry["lowpass_hz"] == 0 else f"{entry['lowpass_hz'] / 1e3:g} kHz"
            lines.append(f"  excitation {entry['excitation_v']:g} V, gain {entry['gain']:g}, low-pass {lowpass}, "
                         f"shunt {'on' if entry['shunt_on'] else 'off'}, "
                         f"{'OVERLOAD' if entry['overloaded'] else 'no overload'}, output {entry['output_v']:.4f} V")
    lines.append("all instruments answered" if report["ok"] else "some instruments did not answer")
    return "\n".join(lines)
