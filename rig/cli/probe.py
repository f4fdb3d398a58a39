"""`hopkinson probe`: bring up a rig step by step, and say what works and what to fix.

    hopkinson probe [--config config/rig.toml] [--json]

1. lists the VISA resources the configured VISA library sees and the serial ports of this
   computer (the names rig.toml wants);
2. opens each configured instrument;
3. reads every mapped signal of the controller one by one (each coil, discrete input and
   register, with its address and type), its identity and watchdog, and judges every value
   against what it can physically be (rig/plausibility.py): a reading that cannot be true
   fails, naming the value, its register and the likely cause (word order, register type,
   unit or scale, with the rig.toml change that makes it plausible); the pulse counter is
   read twice and must not move (unless another process holds the rig); the digitizer's identity,
   every acquisition and channel setting, each recorded channel's on/off state (a scope
   acquires only the channels that are on) and, when it holds a record, each recorded
   channel's transfer and whether it carries its signal (analysis.channel_content: a
   quadrature role must carry the beat, a sensor role the pulse; one that holds only noise
   fails, with the fix, e.g. "unmap the quadrature channel"); the amplifier's identity,
   settings and overload flag;
4. prints each step as ok or FAIL; every failure names the instrument, the command and the
   reply, and a line "fix:" says what to check. A digitizer that does not answer its dialect's
   commands is asked a plain *IDN? (IEEE 488.2, which every dialect answers): its maker then
   names the dialect to set in rig.toml.

It only reads (never the heartbeat, never a coil). While another process holds the rig, it
asks only what can be shared (as `status` does). Once a step has lost an instrument's link, its
remaining steps are listed as not tried (one failure, one fix). Exit code 0 when everything
answered and could be true, 1 when something failed or read a value that cannot be true (the
lines say what to fix), 2 for a bad configuration (docs/exit-codes.md).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import threading
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hopkinson.rig.cli.main import DEFAULT_RIG_CONFIG
from hopkinson.rig.dialect_hint import dialect_fix, plain_identity
from hopkinson.rig.errors import exit_codes_help

if TYPE_CHECKING:
    from hopkinson.rig.config import RigConfig

VISA_SCAN_S = 10.0  # a VISA library's resource scan may broadcast on the network: bounded
# The maker in an *IDN? reply -> the dialect (drivers/scpi_dialect.py) that speaks its commands.


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the `probe` sub-command."""
    probe = subparsers.add_parser(
        "probe", help="bring up a rig: list ports, open each instrument, read every signal, say what to fix",
        description="List VISA resources and serial ports, open each configured instrument, read every mapped "
                    "register and channel setting, and print what works and what does not, with the fix.",
        epilog=exit_codes_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    probe.add_argument("--config", type=Path, default=DEFAULT_RIG_CONFIG, help="rig TOML (default %(default)s)")
    probe.add_argument("--json", action="store_true", help="one JSON object on stdout")
    probe.set_defaults(func=run_probe)


def run_probe(args: argparse.Namespace) -> int:
    from hopkinson.rig.cli.sim import run_report

    return run_report(args, probe_rig, format_probe)


class _Steps:
    """The steps of one instrument: each ok with a value, or failed with the error and the fix."""

    def __init__(self) -> None:
        self.steps: list[dict[str, Any]] = []
        self.link_lost: str | None = None  # the step whose failure lost the link: the rest are not tried

    def run(self, step: str, action: Callable[[], Any]) -> Any:
        from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError
        from hopkinson.rig.errors import ConfigError

        if self.link_lost is not None:  # one failure, one fix: not the same lines for every register
            self.steps.append({"step": step, "ok": None, "value": f"not tried: the link was lost at {self.link_lost}"})
            return None
        try:
            value = action()
        except (InstrumentError, ConfigError, OSError, ValueError) as exc:
            self.steps.append({"step": step, "ok": False, "error": str(exc), "fix": fix_for(exc)})
            if isinstance(exc, InstrumentConnectionError):
                self.link_lost = step
            return None
        self.steps.append({"step": step, "ok": True, "value": _shown(value)})
        return value


def probe_rig(config: RigConfig) -> dict[str, Any]:
    """Every step's outcome (module docstring), as a JSON-ready dict."""
    from hopkinson.rig.cli.sim import instrument_address, lock_holder, shareable

    holder = lock_holder(config)
    report: dict[str, Any] = {"config": config.path, "held_by": holder,
                              "visa_resources": visa_resources(getattr(config.digitizer, "visa_library", "@py")),
                              "serial_ports": serial_ports(), "instruments": {}}
    probes = {"valve_controller": lambda c: _probe_controller(c, held=holder is not None),
              "digitizer": _probe_digitizer, "amplifier": _probe_amplifier}
    for role, probe in probes.items():
        entry: dict[str, Any] = {"address": instrument_address(config, role)}
        if holder is not None and not shareable(config, role):
            entry["skipped"] = f"not asked: the rig is held by pid {holder['pid']} ({holder['command']})"
            entry["steps"] = []
        else:
            entry["steps"] = probe(config).steps
        report["instruments"][role] = entry
    report["ok"] = all(s["ok"] for e in report["instruments"].values() for s in e["steps"])
    return report


def _probe(config: RigConfig, role: str, body: Callable[[_Steps, Any], None]) -> _Steps:
    """Build and open the role's instrument, run `body(steps, instrument)`, close it."""
    from hopkinson.rig.instruments import make_instrument

    steps = _Steps()
    instrument = steps.run("configure the driver", lambda: make_instrument(config, role))
    if instrument is None:
        return steps
    steps.steps[-1]["value"] = type(instrument).__name__
    steps.run("open", instrument.connect)
    if steps.steps[-1]["ok"]:
        try:
            body(steps, instrument)
        finally:
            instrument.close()
    return steps


def _probe_controller(config: RigConfig, held: bool = False) -> _Steps:
    from hopkinson.rig.plausibility import CHECKED_AT_CHECK, PULSE_COUNT

    def body(steps: _Steps, vc: Any) -> None:
        steps.run("identity (read device identification)", vc.identity)
        register_map = getattr(vc, "map", None)
        if register_map is None or not hasattr(vc, "read_bits"):  # a lab's driver: its role's reads, judged
            steps.run("status", vc.status)
            for signal in CHECKED_AT_CHECK:
                if signal != PULSE_COUNT or getattr(vc, "has_pulse_counter", True):
                    steps.run(f"{signal} (plausible?)", lambda s=signal: _judged(vc, config, s))
        else:
            for table, entries in register_map.blocks().items():
                for name, entry in entries.items():
                    steps.run(_signal_step(table, name, entry),
                              lambda t=table, n=name, e=entry: _read_signal(vc, config, t, n, e))
        counted = [st["ok"] for st in steps.steps if st["step"].startswith(PULSE_COUNT)]
        if not held and counted and all(counted):  # read once, and it could be true: must not move
            steps.run(f"{PULSE_COUNT} still (read again after {COUNTER_GAP_S:g} s, nothing fired)",
                      lambda: _counter_still(vc, config))

    return _probe(config, "valve_controller", body)


COUNTER_GAP_S = 0.5  # probe reads the pulse counter twice this far apart: it must not move


def _judged(vc: Any, config: RigConfig, signal: str) -> float:
    """The signal's value; ImplausibleReading (naming the cause and the fix) when it cannot be true."""
    from hopkinson.rig.plausibility import ImplausibleReading, read_and_judge

    value, finding = read_and_judge(vc, config, signal)
    if finding is not None:
        raise ImplausibleReading(finding)
    return value


def _counter_still(vc: Any, config: RigConfig) -> int:
    import time

    from hopkinson.rig.plausibility import (
        PULSE_COUNT,
        ImplausibleReading,
        counter_moved,
        plausible_ranges,
    )

    before = vc.fire_pulse_count()
    time.sleep(COUNTER_GAP_S)
    after = vc.fire_pulse_count()
    finding = counter_moved(plausible_ranges(config)[PULSE_COUNT], before, after, COUNTER_GAP_S)
    if finding is not None:
        raise ImplausibleReading(finding)
    return after


def _signal_step(table: str, name: str, entry: Any) -> str:
    from hopkinson.drivers.registers import Register

    if isinstance(entry, Register):
        span = f"{entry.address}" if entry.words == 1 else f"{entry.address}..{entry.address + 1}"
        scaled = f", x{entry.scale:g}" if entry.scale != 1.0 else ""
        scaled += f" {entry.offset:+g}" if entry.offset else ""
        return f"{table}.{name} ({table.replace('_', ' ')} {span}, {entry.type} {entry.word_order}{scaled})"
    return f"{table}.{name} ({table.replace('_', ' ').rstrip('s')} {entry})"


def _read_signal(vc: Any, config: RigConfig, table: str, name: str, entry: Any) -> Any:
    """A bit, or a register's value judged for plausibility (rig/plausibility.py)."""
    from hopkinson.rig.plausibility import plausible_ranges

    function = table.replace("_", " ")
    if table in ("coils", "discrete_inputs"):
        return vc.read_bits(function, [entry])[entry]
    signal = f"{table}.{name}"
    if signal in plausible_ranges(config):
        value = _judged(vc, config, signal)
        return int(value) if isinstance(entry, int) else value
    if isinstance(entry, int):
        return vc.read_words(function, [entry])[entry]
    return vc.read_values(function, {"value": entry})["value"]


def _probe_digitizer(config: RigConfig) -> _Steps:
    def body(steps: _Steps, dig: Any) -> None:
        steps.run("identity (*IDN?)", dig.identity)
        settings = steps.run("acquisition and channel settings", dig.settings) if hasattr(dig, "settings") else None
        configured = getattr(config.digitizer, "settings", None)
        if settings is not None and callable(configured) and hasattr(settings, "differences"):
            steps.run("settings against rig.toml", lambda: _same(configured().differences(settings)))
        roles = dict(getattr(dig, "channels", {}) or {})
        if settings is not None and getattr(settings, "channels_on", None) is not None:
            steps.run("recorded channels on", lambda: channel_states(settings.channels_on, roles))
        state = steps.run("acquisition state", dig.acquisition_state)
        if state == "TRIGGERED":  # the instrument holds a record: each role's transfer, and what it carries
            volts: dict[str, Any] = {}

            def transfer(role: str) -> str:
                waveform = dig.fetch_waveform(role)
                volts[role] = waveform.volts()
                return f"{waveform.codes.size} samples"

            for role, channel in roles.items():
                steps.run(f"transfer of {channel} ({role})", lambda role=role: transfer(role))
            for role, channel in roles.items():
                if role != "doppler" and role in volts and "doppler" in volts:
                    steps.run(f"{role} ({channel}) carries its signal", lambda role=role: _content(role, volts))

    steps = _probe(config, "digitizer", body)
    opened = [s for s in steps.steps if s["step"] == "open"]
    if opened and not opened[0]["ok"]:  # reached or not: a plain *IDN? tells what answers there
        identity = plain_identity(config)
        if identity:
            steps.steps.append({"step": "identity by a plain *IDN? (IEEE 488.2)", "ok": True, "value": identity})
            fix = dialect_fix(config, identity)
            if fix is not None:
                opened[0]["fix"] = fix
    return steps


class EmptyChannel(ValueError):
    """A recorded channel that carries nothing for its role (analysis.channel_content)."""

    def __init__(self, message: str, fix: str) -> None:
        super().__init__(message)
        self.fix = fix


def _content(role: str, volts: dict[str, Any]) -> str:
    """How much the role's channel rises while the doppler channel's beat runs; EmptyChannel
    when it carries nothing (a quadrature role on a one-photodetector interferometer, a sensor
    role with no sensor)."""
    from hopkinson.analysis.channel_content import beat_content, pulse_content

    judge = beat_content if role == "doppler_quadrature" else pulse_content
    content = judge(volts[role], volts["doppler"], role)
    if content is None:
        return "not judged: the doppler channel shows no motion in this record"
    if content.carries_nothing:
        raise EmptyChannel(content.message(), content.fix())
    return f"rises {content.rise_db:.0f} dB while the object moves"


def channel_states(channels_on: dict[str, bool], roles: dict[str, str]) -> str:
    """'CHAN1 on (doppler), CHAN2 off (response)' and, when one is off, that ARM turns it on."""
    names = {channel: role for role, channel in roles.items()}
    text = ", ".join(f"{ch} {'on' if on else 'off'}" + (f" ({names[ch]})" if ch in names else "")
                     for ch, on in channels_on.items())
    if all(channels_on.values()):
        return text
    return text + ": a channel that is off is not acquired; the sequencer turns it on at ARM"


def _same(differences: list[str]) -> str:
    """Not a failure: the sequencer configures the digitizer and reads it back before a shot."""
    if differences:
        return "not set as in rig.toml yet (the sequencer sets it before a shot): " + "; ".join(differences)
    return "as in rig.toml"


def _probe_amplifier(config: RigConfig) -> _Steps:
    def body(steps: _Steps, amp: Any) -> None:
        steps.run("identity", amp.identity)
        steps.run("settings", amp.settings)
        steps.run("overload flag", amp.overloaded)

    return _probe(config, "amplifier", body)


def visa_resources(library: str) -> dict[str, Any]:
    """The VISA resources `library` lists (bounded in time), or why it could not."""
    result: dict[str, Any] = {"library": library}

    def scan() -> None:
        try:
            import pyvisa

            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # pyvisa-py's notes on optional discovery packages
                manager = pyvisa.ResourceManager(library)
                try:
                    result["resources"] = list(manager.list_resources())
                finally:
                    manager.close()
        except Exception as exc:  # a missing or broken VISA library: reported, not raised
            result["error"] = f"{type(exc).__name__}: {exc}"

    thread = threading.Thread(target=scan, name="probe-visa", daemon=True)
    thread.start()
    thread.join(VISA_SCAN_S)
    if thread.is_alive():
        result["error"] = f"the VISA library did not list its resources within {VISA_SCAN_S:g} s"
    return result


def serial_ports() -> list[dict[str, str]]:
    """This computer's serial ports (device, description)."""
    from serial.tools import list_ports

    return [{"device": p.device, "description": p.description or ""} for p in list_ports.comports()]


FIXES: list[tuple[str, str]] = [  # (text in the error, what to check), first match wins
    ("not running for this user", "start the simulator: `hopkinson sim` (or use --config with real addresses)"),
    ("could not connect", "check host and port in rig.toml, that the device is powered and on this network "
                          "(ping it), and that no firewall blocks the port"),
    ("lock", "another process holds the port: `hopkinson status` names it; stop it or wait"),
    ("No such file", "the port does not exist: pick one from the serial ports listed above"),
    ("Permission denied", "this user may not open the port: add it to the port's group (e.g. dialout)"),
    ("exception 11", "wrong unit id: set valve_controller.unit_id to the controller's Modbus address"),
    ("exception 2", "the address is not mapped in the device: compare rig.toml's register map with the "
                    "PLC's documentation (0-based protocol addresses, not 4xxxx numbers)"),
    ("exception 1", "the device does not support this function: is the signal in the right table "
                    "(coil, discrete input, holding or input register)?"),
    ("no reply within", "nothing answered: check the unit id, baud rate, parity and stop bits, the wiring "
                        "(RS-485 A/B swapped?) and the termination"),
    ("longer than", "the reply is not this protocol: is another device or protocol on this port?"),
    ("cannot import", "install the lab's driver package in this environment, or put it on PYTHONPATH"),
    ("VISA", "check the resource string against the VISA resources listed above, and the VISA library"),
]


def fix_for(exc: BaseException) -> str:
    """What to check for this failure (its own fix, FIXES), or the general advice."""
    own = getattr(exc, "fix", None)
    if isinstance(own, str) and own:
        return own
    text = str(exc)
    off = re.search(r"(\S+) is off on the instrument", text)
    if off:
        return (f"turn {off.group(1)} on at the instrument (a shot's ARM turns on every channel rig.toml records "
                "and checks it before FIRE): another program or the front panel turned it off")
    for needle, fix in FIXES:
        if needle.lower() in text.lower():
            return fix
    return "check the instrument's settings against rig.toml and its manual"


def _shown(value: Any) -> Any:
    if isinstance(value, bool | int | float | str) or value is None:
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {k: v for k, v in dataclasses.asdict(value).items() if v is not None}
    return str(value)


def format_probe(report: dict[str, Any]) -> str:
    """The probe report as lines for a person."""
    lines = [f"probe: {report['config']}"]
    visa = report["visa_resources"]
    found = ", ".join(visa.get("resources", [])) or "none"
    lines.append(f"VISA resources ({visa['library']}): {found}" if "error" not in visa
                 else f"VISA resources ({visa['library']}): cannot list: {visa['error']}")
    ports = ", ".join(f"{p['device']} ({p['description']})" if p["description"] and p["description"] != "n/a"
                      else p["device"] for p in report["serial_ports"]) or "none"
    lines.append(f"serial ports: {ports}")
    if report.get("held_by"):
        h = report["held_by"]
        lines.append(f"the rig is held by pid {h['pid']} ({h['command']}): probing only what can be shared")
    failed = passed = 0
    titles = {"valve_controller": "valve/vacuum controller", "digitizer": "digitizer", "amplifier": "amplifier"}
    for role, entry in report["instruments"].items():
        lines.append(f"{titles[role]} ({entry['address']}):")
        if "skipped" in entry:
            lines.append(f"  --    {entry['skipped']}")
        for step in entry["steps"]:
            if step["ok"] is None:  # not tried (the link was lost before it)
                lines.append(f"  --    {step['step']}: {step['value']}")
            elif step["ok"]:
                passed += 1
                shown = "" if step["value"] is None else f": {step['value']}"
                lines.append(f"  ok    {step['step']}{shown}")
            else:
                failed += 1
                lines.append(f"  FAIL  {step['step']}: {step['error']}")
                lines.append(f"        fix: {step['fix']}")
    lines.append(f"{passed} ok, {failed} failed" + ("" if failed else ": the rig answers as configured"))
    return "\n".join(lines)
