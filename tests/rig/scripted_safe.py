"""A scripted valve controller and digitizer for unit tests of SAFE's logic
(rig/sequencer/safe.py) and of the interlock rules (rig/interlocks.py), and `run`, SAFE on them;
used by test_mutants_safe.py and test_mutants_interlocks.py (the real protocols are tested in
test_sequencer_faults.py and test_cli_safe.py).
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from hopkinson.drivers.roles import Interlocks, ValveStates
from hopkinson.rig.config import LimitsConfig
from hopkinson.rig.events import EventBus, RigEvent
from hopkinson.rig.sequencer import safe
from hopkinson.rig.sequencer.context import Publisher
from hopkinson.rig.sequencer.safe import make_rig_safe

NAME = "valve controller 127.0.0.1:5020"
LIMITS = LimitsConfig(max_pressure_bar=8.0, min_pressure_bar=0.2, pressure_tolerance_bar=0.05,
                      fixture_vacuum_max_mbar=100.0, vent_done_bar=0.05)
POLL_S = 0.005


def config(safe_s: float = 0.3, controller_timeout_s: float = 0.05, resolution_bar: float = 0.0) -> Any:
    """The parts of a RigConfig SAFE reads."""
    return SimpleNamespace(limits=LIMITS, timeouts=SimpleNamespace(safe_s=safe_s),
                           valve_controller=SimpleNamespace(timeout_s=controller_timeout_s,
                                                            gauge_resolution_bar=resolution_bar))


class Controller:
    """A scripted valve controller: coils follow commands unless a valve is stuck (its position
    then stays); `failures` maps a method name to the exceptions its next calls raise."""

    name = NAME

    def __init__(self, pressure_bar: float = 0.0, stuck: dict[str, bool] | None = None, positions: bool = True,
                 pump_stays_on: bool = False) -> None:
        self.coils = {"fire_valve": True, "fill_valve": True, "vent_valve": False, "vacuum_pump": True}
        self.stuck = stuck or {}
        self.positions = positions
        self.pump_stays_on = pump_stays_on
        self.pressures = [pressure_bar]
        self.commands: list[tuple[str, bool]] = []
        self.failures: dict[str, list[BaseException | None]] = {}

    def _maybe_fail(self, method: str) -> None:
        queue = self.failures.get(method)
        if queue:
            failure = queue.pop(0)
            if failure is not None:  # None: this call succeeds
                raise failure

    def _set(self, name: str, value: bool) -> None:
        self._maybe_fail(f"set_{name}")
        self.commands.append((name, value))
        if not (name == "vacuum_pump" and self.pump_stays_on):
            self.coils[name] = value

    def set_fire_valve(self, value: bool) -> None:
        self._set("fire_valve", value)

    def set_fill_valve(self, value: bool) -> None:
        self._set("fill_valve", value)

    def set_vent_valve(self, value: bool) -> None:
        self._set("vent_valve", value)

    def set_vacuum_pump(self, value: bool) -> None:
        self._set("vacuum_pump", value)

    def valves(self) -> ValveStates:
        self._maybe_fail("valves")
        positions = {f"{v}_position": self.stuck.get(v, self.coils[v]) if self.positions else None
                     for v in ("fire_valve", "fill_valve", "vent_valve")}
        return ValveStates(**self.coils, **positions)

    def interlocks(self) -> Interlocks:
        self._maybe_fail("interlocks")
        return Interlocks(door_closed=True, fixture_clamped=False, estop_healthy=True)

    def reservoir_pressure_bar(self) -> float:
        self._maybe_fail("reservoir_pressure_bar")
        return self.pressures.pop(0) if len(self.pressures) > 1 else self.pressures[0]

    def fixture_vacuum_mbar(self) -> float:
        return 990.0


class Digitizer:
    def __init__(self, connected: bool = True) -> None:
        self.connected = connected
        self.aborts = 0

    def abort(self) -> None:
        self.aborts += 1


class Events(Publisher):
    def __init__(self) -> None:
        super().__init__(EventBus())
        self.seen: list[RigEvent] = []
        self.bus.subscribe(self.seen.append)

    def of(self, kind: type) -> list[Any]:
        return [e for e in self.seen if isinstance(e, kind)]


def run(controller: Controller, cfg: Any = None, sleep: Any = None, events: Events | None = None,
        **kw: Any) -> tuple[safe.SafeResult, Events]:
    """SAFE on the scripted controller; `sleep` stands in for time.sleep between polls (the
    test moves the scripted rig there), restored afterwards."""
    events = Events() if events is None else events
    original = safe.time.sleep
    if sleep is not None:
        safe.time.sleep = sleep
    try:
        result = make_rig_safe(controller, cfg or config(), events, poll_s=POLL_S, **kw)
    finally:
        safe.time.sleep = original
    return result, events

