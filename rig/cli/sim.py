"""`hopkinson sim` (run the simulated rig) and `hopkinson status` (ask every instrument).

    hopkinson sim [--config config/sim.toml] [--fault NAME ...] [--digitizer-dialect NAME]
                  [--addresses-json PATH]
    hopkinson sim --list-faults
    hopkinson status [--config config/rig.toml] [--json]

`sim` prints the addresses (Modbus, VISA resource, serial ports) and runs until Ctrl-C or
SIGTERM, then stops its servers and exits 0; its ptys, addresses and state live in the
per-user runtime folder (drivers/sim/simulated_rig.py). The digitizer speaks the dialect of
sim.toml's `servers.digitizer_dialect` or --digitizer-dialect; `sim` prints the [digitizer]
dialect and channels a rig config needs to reach it.

`status` asks each instrument through its role (drivers/roles.py) and reports identity,
pressures, vacuum, valves (commanded and real), interlocks, watchdog, the amplifier's
settings. It only reads: it never writes the heartbeat or anything else. While a shot,
campaign or panel holds the rig (rig/lock.py), it names the holder and asks only what can be
shared without disturbing it: the controller over Modbus TCP (a second connection), never a
held serial line or the digitizer's session. An instrument that cannot be reached is
reported with the reason and the others are still asked. Exit code 0 when every instrument
asked answered, 1 when one did not, 2 for a bad configuration.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.rig.cli.main import DEFAULT_RIG_CONFIG, DEFAULT_SIM_CONFIG, emit_json, fail

if TYPE_CHECKING:
    from hopkinson.drivers.roles import AmplifierRole, DigitizerRole, ValveControllerRole
    from hopkinson.rig.config import RigConfig

ROLE_TITLES = {"valve_controller": "valve/vacuum controller", "digitizer": "digitizer", "amplifier": "amplifier"}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `sim` and `status` sub-commands."""
    sim = subparsers.add_parser(
        "sim", help="run the simulated rig (Modbus, VISA socket, serial pty) until Ctrl-C",
        description="Run the simulated rig: valve/vacuum controller (Modbus TCP), digitizer "
                    "(SCPI socket) and bridge amplifier (serial pty), driven by one physics model.")
    sim.add_argument("--config", type=Path, default=DEFAULT_SIM_CONFIG, help="simulator TOML (default %(default)s)")
    sim.add_argument("--fault", action="append", default=[], metavar="NAME",
                     help="inject a named fault (repeatable; see --list-faults)")
    sim.add_argument("--digitizer-dialect", metavar="NAME",
                     help="the simulated digitizer's command set: generic, keysight, tektronix or lecroy "
                          "(default: the simulator TOML's servers.digitizer_dialect)")
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
    from hopkinson.drivers.sim.scpi_digitizer import SIM_DIALECTS
    from hopkinson.drivers.sim.simulated_rig import fault_list_text, run_simulator
    from hopkinson.rig.config import load_sim_config
    from hopkinson.rig.instruments import sim_digitizer_lines

    if args.list_faults:
        print(fault_list_text())
        return 0
    unknown = [name for name in args.fault if name not in FAULTS]
    if unknown:
        return fail(f"unknown fault {unknown[0]!r}; known: {', '.join(FAULTS)}")
    if args.digitizer_dialect is not None and args.digitizer_dialect not in SIM_DIALECTS:
        return fail(f"--digitizer-dialect: unknown dialect {args.digitizer_dialect!r}; known: {', '.join(SIM_DIALECTS)}")
    config = load_sim_config(args.config)
    if args.digitizer_dialect is not None:
        config = replace(config, servers=replace(config.servers, digitizer_dialect=args.digitizer_dialect))
    try:
        return run_simulator(config, args.fault, args.addresses_json,
                             notes=lambda a: sim_digitizer_lines(a.digitizer_dialect, a.digitizer_channels))
    except (OSError, RuntimeError) as exc:
        return fail(f"cannot start the simulated rig ({args.config}): {exc}")


# -- status ---------------------------------------------------------------------------------------
def run_status(args: argparse.Namespace) -> int:
    return run_report(args, rig_status, format_status)


def run_report(args: argparse.Namespace, build: Any, text: Any) -> int:
    """Load --config, build a report (a dict with "ok"), print it (--json or as text);
    exit 0 when ok, else 1 (status and probe)."""
    from hopkinson.rig.config import load_rig_config

    report = build(load_rig_config(args.config))
    if args.json:
        emit_json(report)
    else:
        print(text(report))
    return 0 if report["ok"] else 1


def rig_status(config: RigConfig) -> dict[str, Any]:
    """Ask every instrument (reads only); a failure is recorded under its name, never raised."""
    from hopkinson.rig.instruments import make_instrument

    holder = lock_holder(config)
    report: dict[str, Any] = {"config": config.path, "held_by": holder}
    asks = {"valve_controller": _valve_controller_status, "digitizer": _digitizer_status,
            "amplifier": _amplifier_status}
    for role, ask in asks.items():
        address = instrument_address(config, role)
        if holder is not None and not shareable(config, role):
            report[role] = {"address": address, "ok": True, "skipped": f"not asked: the rig is held by pid "
                            f"{holder['pid']} ({holder['command']}) and this link cannot be shared"}
            continue
        report[role] = _ask(address, lambda role=role, ask=ask: ask(make_instrument(config, role)))
    report["ok"] = all(report[k]["ok"] for k in asks)
    return report


def lock_holder(config: RigConfig) -> dict[str, Any] | None:
    """Who holds the rig (rig/lock.py: pid, command, since), or None."""
    from hopkinson.rig.lock import current_holder

    holder = current_holder(config)
    if holder is None:
        return None
    return {"pid": holder.pid, "command": holder.command, "since": holder.since}


def shareable(config: RigConfig, role: str) -> bool:
    """Can a reader ask this instrument while another process drives the rig? Only a Modbus
    TCP controller: a serial line is exclusive, a digitizer session is the shot's."""
    vc = config.valve_controller
    return role == "valve_controller" and vc.driver == "modbus" and vc.transport == "tcp"


def instrument_address(config: RigConfig, role: str) -> str:
    """Where an instrument is, as the report shows it."""
    if role == "valve_controller":
        return config.valve_controller.address
    if role == "digitizer":
        return config.digitizer.resource
    amp = config.amplifier
    return amp.port if amp.driver == "serial-bridge" else f"{amp.driver} (no link)" if amp.driver == "manual" \
        else amp.driver


def _ask(address: str, query: Any) -> dict[str, Any]:
    from hopkinson.drivers.errors import InstrumentError
    from hopkinson.rig.errors import ConfigError

    try:
        return {"address": address, "ok": True, **query()}
    except (InstrumentError, ConfigError, OSError, ValueError) as exc:
        return {"address": address, "ok": False, "error": str(exc)}


def _identity(instrument: Any) -> str:
    from hopkinson.drivers.errors import InstrumentError

    try:
        return instrument.identity()
    except InstrumentError as exc:  # identification is optional in Modbus: report, go on
        return f"(no identification: {exc.problem})"


def _valve_controller_status(vc: ValveControllerRole) -> dict[str, Any]:
    with vc:
        identity = _identity(vc)
        status = vc.status()
    return {
        "identity": identity,
        "reservoir_pressure_bar": status.reservoir_pressure_bar,
        "pressure_setpoint_bar": status.pressure_setpoint_bar,
        "fixture_vacuum_mbar": status.fixture_vacuum_mbar,
        "valves": {k: v for k, v in asdict(status.valves).items() if v is not None},
        "valve_problems": status.valves.mismatches(),
        "interlocks": asdict(status.interlocks),
        "interlock_problems": status.interlocks.problems(),
        "watchdog": status.watchdog,
        "fire_pulse_count": status.fire_pulse_count,
    }


def _digitizer_status(dig: DigitizerRole) -> dict[str, Any]:
    with dig:
        if hasattr(dig, "settings"):
            settings = dig.settings()
            rate, length = settings.sample_rate_hz, settings.record_length
        else:  # transitional: a digitizer driver from before the DigitizerRole's settings()
            rate, length = dig.sample_rate_hz(), dig.record_length()  # type: ignore[attr-defined]
        return {"identity": _identity(dig), "state": dig.acquisition_state(), "sample_rate_hz": rate,
                "record_length": length}


def _amplifier_status(amp: AmplifierRole) -> dict[str, Any]:
    with amp:
        settings = amp.settings()
        return {**settings.to_dict(), "identity": settings.identity or _identity(amp), "overloaded": amp.overloaded()}


def format_status(report: dict[str, Any]) -> str:
    """The status report as lines for a person."""
    lines = [f"config: {report['config']}"]
    holder = report.get("held_by")
    if holder:
        lines.append(f"the rig is held by pid {holder['pid']} ({holder['command']}, since {holder['since']}): "
                     "reading only what can be shared")
    for key, title in ROLE_TITLES.items():
        entry = report[key]
        if "skipped" in entry:
            lines.append(f"{title} ({entry['address']}): {entry['skipped']}")
            continue
        if not entry["ok"]:
            lines.append(f"{title} ({entry['address']}): NOT REACHABLE: {entry['error']}")
            continue
        lines.append(f"{title} ({entry['address']}): {entry['identity']}")
        if key == "valve_controller":
            lines += _controller_lines(entry)
        elif key == "digitizer":
            lines.append(f"  state {entry['state']}, {entry['sample_rate_hz'] / 1e6:g} MS/s, "
                         f"{entry['record_length']} samples")
        else:
            lowpass = "off" if entry["lowpass_hz"] == 0 else f"{entry['lowpass_hz'] / 1e3:g} kHz"
            lines.append(f"  gain {entry['gain']:g}, excitation {entry['excitation_v']:g} V, low-pass {lowpass} "
                         f"({entry['source']}), {'OVERLOAD' if entry['overloaded'] else 'no overload'}")
    skipped = [key for key in ("valve_controller", "digitizer", "amplifier")
               if isinstance(report.get(key), dict) and report[key].get("skipped")]
    if not report["ok"]:
        lines.append("some instruments did not answer")
    elif skipped:
        lines.append(f"the instruments asked answered; not asked: {', '.join(k.replace('_', ' ') for k in skipped)}")
    else:
        lines.append("all instruments answered")
    return "\n".join(lines)


def _controller_lines(entry: dict[str, Any]) -> list[str]:
    v = entry["valves"]

    def valve(name: str) -> str:
        told = "open" if v[name] else "shut"
        real = v.get(f"{name}_position")
        return told if real is None or real == v[name] else f"{told} (really {'open' if real else 'shut'})"

    valves = (f"fire {valve('fire_valve')}, fill {valve('fill_valve')}, vent {valve('vent_valve')}, "
              f"pump {'on' if v['vacuum_pump'] else 'off'}")
    problems = ", ".join(entry["interlock_problems"]) or "all safe"
    lines = [
        f"  reservoir pressure {entry['reservoir_pressure_bar']:.3f} bar "
        f"(set-point {entry['pressure_setpoint_bar']:.3f} bar)",
        f"  fixture vacuum     {entry['fixture_vacuum_mbar']:.1f} mbar",
        f"  valves             {valves}",
        f"  interlocks         {problems}",
    ]
    if entry["watchdog"]:
        count = entry["fire_pulse_count"]
        lines.append(f"  link watchdog      {entry['watchdog']}"
                     + (f", {count} fire pulses" if count is not None else ""))
    if entry["valve_problems"]:
        lines.append(f"  WARNING            {'; '.join(entry['valve_problems'])}")
    return lines
