"""SAFE (rig/sequencer/safe.py) and the interlock rules (rig/interlocks.py), unit by unit.

These kill the mutants the sequencer's fault-injection tests let survive (docs/mutation-testing.md):
each branch of SAFE's confirmation, its messages and its hold after a controller timeout, on a
scripted controller (a unit test of SAFE's logic; the real protocols are tested in
test_sequencer_faults.py and test_cli_safe.py), and every interlock rule at its bounds.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.drivers.roles import Interlocks, ValveStates
from hopkinson.rig.config import LimitsConfig
from hopkinson.rig.errors import HINT_SAFE_NOT_CONFIRMED
from hopkinson.rig.events import EventBus, Note, Reading, RigError, RigEvent, RigWarning
from hopkinson.rig.interlocks import (
    INTERLOCKS,
    REQUIRED,
    InterlockCode,
    RigReadings,
    controller_readings,
    evaluate,
    pressure_check,
    read_readings,
)
from hopkinson.rig.plausibility import RESERVOIR, Implausible, judge, plausible_ranges
from hopkinson.rig.sequencer import safe
from hopkinson.rig.sequencer.context import Publisher
from hopkinson.rig.sequencer.safe import gauge_half_count_bar, make_rig_safe, safe_hold_s

NAME = "valve controller 127.0.0.1:5020"
LIMITS = LimitsConfig(max_pressure_bar=8.0, min_pressure_bar=0.2, pressure_tolerance_bar=0.05,
                      fixture_vacuum_max_mbar=100.0, vent_done_bar=0.05)
POLL_S = 0.005
# Each test here takes well under 2 s; a mutant that keeps SAFE from ever returning fails at 30 s.
pytestmark = pytest.mark.timeout(30)


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


# -- SAFE -----------------------------------------------------------------------------------------------
def test_fast_path_commands_every_actuator_once_then_confirms_by_reading_back() -> None:
    controller, digitizer = Controller(pressure_bar=0.01), Digitizer()
    result, events = run(controller, digitizer=digitizer)
    assert controller.commands == [("fire_valve", False), ("fill_valve", False), ("vent_valve", True),
                                   ("vacuum_pump", False)]
    assert digitizer.aborts == 1
    assert result.confirmed and result.problem is None and result.interrupt is None
    assert result.controller_timed_out is False
    assert result.reservoir_pressure_bar == 0.01
    assert result.valves == controller.valves()
    assert 0.0 <= result.elapsed_s < 0.3
    (note,) = events.of(Note)
    assert note.message.startswith("rig safe: fire and fill closed, vent open, pump off, reservoir 0.010 bar")
    assert not events.of(RigError)
    (reading,) = events.of(Reading)  # the gauges shown while SAFE runs: the display interlocks only
    assert reading.interlocks == {"door": True, "clamp": False, "estop": True, "vacuum": False, "pressure": True}


def test_the_options_are_keyword_only() -> None:
    with pytest.raises(TypeError):
        make_rig_safe(Controller(), config(), Events(), Digitizer())  # type: ignore[misc]


def test_a_disconnected_digitizer_is_still_asked_one_that_fails_is_said_and_none_is_fine() -> None:
    """Issue 45 item 2 (SAFE never leaves the digitizer armed unsaid): a digitizer whose link an
    error closed is asked all the same (its driver reopens the link, or refuses at once when it
    never had one); one that cannot be disarmed is a warning, never a reason to stop SAFE."""
    digitizer = Digitizer(connected=False)
    assert run(Controller(), digitizer=digitizer)[0].confirmed
    assert digitizer.aborts == 1

    class Hung(Digitizer):
        def abort(self) -> None:
            raise InstrumentError("digitizer", "abort", "reply longer than 65536 bytes")

    result, events = run(Controller(), digitizer=Hung())
    assert result.confirmed
    (warning,) = events.of(RigWarning)
    assert warning.message.startswith("SAFE could not disarm the digitizer (digitizer: 'abort': reply longer than")
    assert run(Controller())[0].confirmed


def test_a_valve_read_back_wrong_is_commanded_again_until_it_moves() -> None:
    controller = Controller()
    controller.stuck = {"vent_valve": False}
    events = Events()

    def free_the_vent(_: float) -> None:
        controller.stuck = {}

    result, _ = run(controller, sleep=free_the_vent, events=events)  # the vent moves during the first poll
    assert result.confirmed
    assert controller.commands.count(("vent_valve", True)) == 2  # the fast path, then once again
    assert controller.commands.count(("fire_valve", False)) == 1


@pytest.mark.parametrize(("stuck", "positions", "text"), [
    ({"fill_valve": True}, True, "fill valve open (commanded shut), wanted shut after 0.3 s"),
    ({"vent_valve": False}, True, "vent valve shut (commanded open), wanted open after 0.3 s"),
    ({"fire_valve": True}, True, "fire valve open (commanded shut), wanted shut after 0.3 s"),
])
def test_not_confirmed_names_each_stuck_valve_and_what_it_was_told(stuck, positions, text) -> None:
    controller = Controller(stuck=stuck, positions=positions)
    result, events = run(controller)
    assert not result.confirmed
    assert result.problem == f"{NAME}: {text}"
    (error,) = events.of(RigError)
    assert error.message == f"SAFE NOT CONFIRMED: {NAME}: {text}"
    assert error.source == NAME and error.hint == HINT_SAFE_NOT_CONFIRMED
    assert not events.of(Note)
    assert result.elapsed_s >= 0.3


def test_a_coil_that_will_not_change_without_position_inputs_is_named_as_a_coil() -> None:
    controller = Controller(positions=False, pump_stays_on=True)
    result, _ = run(controller)
    assert result.problem == f"{NAME}: vacuum pump still on"
    controller = Controller(positions=False)
    controller.set_fire_valve = lambda value: None  # the coil never drops
    result, _ = run(controller)
    assert result.problem == f"{NAME}: fire valve open (coil), wanted shut after 0.3 s"


def test_a_valve_open_behind_a_coil_that_reads_off_is_not_as_wanted() -> None:
    """Both the coil and the valve must be as wanted (`_as_wanted`): a vent valve whose position
    reads open while its coil reads off (a coil that will not energise; the valve held open by
    something else) is not a vent SAFE commanded, and is named with what it was told."""
    controller = Controller(stuck={"vent_valve": True})
    controller.set_vent_valve = lambda value: None  # the coil stays off
    result, _ = run(controller)
    assert not result.confirmed
    assert result.problem == f"{NAME}: vent valve open (commanded shut), wanted open after 0.3 s"

def test_a_reservoir_still_under_pressure_is_not_confirmed_and_says_so() -> None:
    result, _ = run(Controller(pressure_bar=1.2345))
    assert not result.confirmed
    assert result.problem == (f"{NAME}: reservoir still at 1.234 bar after venting for 0.3 s (needs at most "
                              "0.05 bar; fill valve stuck open?)")
    assert result.reservoir_pressure_bar == 1.2345


@pytest.mark.parametrize(("pressure_bar", "resolution_attr", "resolution_config", "confirmed"), [
    (0.05, None, 0.0, True),           # at the limit, a float gauge: vented
    (0.0501, None, 0.0, False),
    (0.04, 0.02, 0.0, True),           # 0.04 + half a 0.02 count = 0.05: at the limit
    (0.0401, 0.02, 0.0, False),
    (0.0401, None, 0.02, False),       # the configured resolution when the driver has none
    (0.04, None, 0.02, True),
])
def test_vented_means_the_reading_plus_half_a_gauge_count_at_most_the_limit(
        pressure_bar, resolution_attr, resolution_config, confirmed) -> None:
    controller = Controller(pressure_bar=pressure_bar)
    controller.pressure_resolution_bar = resolution_attr
    result, _ = run(controller, config(resolution_bar=resolution_config))
    assert result.confirmed is confirmed


def test_gauge_half_count() -> None:
    controller = Controller()
    assert gauge_half_count_bar(controller, config(resolution_bar=0.01)) == 0.005
    controller.pressure_resolution_bar = 0.002
    assert gauge_half_count_bar(controller, config(resolution_bar=0.01)) == 0.001


def test_an_instrument_error_in_a_round_delays_the_confirmation_to_a_clean_round() -> None:
    controller = Controller()
    controller.failures["interlocks"] = [InstrumentError(NAME, "read inputs", "no reply")]
    result, events = run(controller)
    assert result.confirmed and result.problem is None
    assert len(events.of(Reading)) == 1  # the failed round had no reading to show


@pytest.mark.parametrize("method", ["valves", "interlocks", "reservoir_pressure_bar"])
def test_an_error_on_every_round_is_not_confirmed_and_the_error_is_the_problem(method) -> None:
    controller = Controller()
    controller.failures[method] = [InstrumentError(NAME, method, "connection lost")] * 1000
    result, events = run(controller)
    assert not result.confirmed
    assert result.problem == str(InstrumentError(NAME, method, "connection lost"))
    assert events.of(RigError)[0].message == f"SAFE NOT CONFIRMED: {result.problem}"


def test_an_error_after_a_stuck_valve_was_read_names_the_valve_too() -> None:
    controller = Controller(stuck={"fill_valve": True})
    controller.failures["interlocks"] = [InstrumentError(NAME, "read inputs", "connection lost")] * 1000
    result, _ = run(controller)
    assert result.problem == (f"{InstrumentError(NAME, 'read inputs', 'connection lost')}; last read back: "
                              "fill valve commanded shut but open")
    assert result.valves.fill_valve_position is True


def test_a_round_whose_re_command_fails_is_not_clean_so_the_error_is_the_problem() -> None:
    """A stuck fill valve whose command is carried out but answered with an error (the coil drops,
    the reply is lost): every round has an instrument error, so the problem is that error and the
    valve last read, not a clean round's account."""
    controller = Controller(stuck={"fill_valve": True})
    error = InstrumentError(NAME, "write coil fill", "no reply")

    def set_fill(value: bool) -> None:
        controller.coils["fill_valve"] = value
        raise error

    controller.set_fill_valve = set_fill
    result, _ = run(controller)
    assert result.problem == f"{error}; last read back: fill valve commanded shut but open"


def test_an_error_with_no_stuck_valve_read_is_only_the_error() -> None:
    controller = Controller()
    controller.failures["interlocks"] = [InstrumentError(NAME, "read inputs", "connection lost")] * 1000
    assert run(controller)[0].problem == str(InstrumentError(NAME, "read inputs", "connection lost"))


def test_an_unexpected_exception_is_reported_and_the_other_steps_still_run() -> None:
    controller = Controller()
    controller.failures["set_fire_valve"] = [ValueError("bad register")] * 1000
    result, _ = run(controller)
    assert not result.confirmed
    assert result.problem == "sequencer: unexpected error: ValueError: bad register"
    assert ("fill_valve", False) in controller.commands and ("vent_valve", True) in controller.commands


def test_an_interrupt_is_held_until_the_rig_is_safe_and_handed_back() -> None:
    controller = Controller()
    first, second = KeyboardInterrupt(), KeyboardInterrupt()
    controller.failures["set_fire_valve"] = [first]
    controller.failures["set_fill_valve"] = [second]
    result, _ = run(controller)
    assert result.confirmed
    assert result.interrupt is first  # the first one held, the second not lost the rig
    assert ("vent_valve", True) in controller.commands


def test_an_interrupt_while_polling_is_held() -> None:
    controller = Controller(stuck={"vent_valve": False})
    interrupt = KeyboardInterrupt()
    calls = []

    def sleep(_: float) -> None:
        calls.append(1)
        if len(calls) == 1:
            raise interrupt
        controller.stuck = {}

    result, _ = run(controller, sleep=sleep)
    assert result.confirmed and result.interrupt is interrupt


def test_an_interrupt_while_polling_does_not_replace_one_already_held() -> None:
    controller = Controller(stuck={"vent_valve": False})
    first = KeyboardInterrupt()
    controller.failures["set_fire_valve"] = [first]
    calls = []

    def sleep(_: float) -> None:
        calls.append(1)
        if len(calls) == 1:
            raise KeyboardInterrupt()
        controller.stuck = {}

    result, _ = run(controller, sleep=sleep)
    assert result.interrupt is first


@pytest.mark.parametrize(("timeout_s", "safe_s", "hold_s"), [
    (0.05, 20.0, 1.0),   # at least 1 s
    (0.5, 20.0, 2.0),    # four controller timeouts
    (0.5, 3.0, 1.5),     # at most half of SAFE's time
])
def test_safe_hold_s(timeout_s, safe_s, hold_s) -> None:
    assert safe_hold_s(config(safe_s=safe_s, controller_timeout_s=timeout_s)) == hold_s


def test_after_a_controller_timeout_safe_holds_before_it_confirms() -> None:
    controller = Controller()
    controller.failures["valves"] = [InstrumentTimeout(NAME, "read coils", "no reply")]
    cfg = config(safe_s=2.5)  # hold: max(1, 4 x 0.05) = 1 s
    result, _ = run(controller, cfg)
    assert result.confirmed and result.controller_timed_out
    assert result.elapsed_s >= 1.0
    result, _ = run(Controller(), cfg, controller_timed_out=True)  # a timeout before SAFE began
    assert result.confirmed and result.controller_timed_out and result.elapsed_s >= 1.0


@pytest.mark.parametrize("other", ["digitizer TCPIP::127.0.0.1::5025::SOCKET", "zeta digitizer"])
def test_a_timeout_of_another_instrument_is_no_reason_to_hold(other: str) -> None:
    controller = Controller()
    digitizer = Digitizer()

    def late() -> None:
        raise InstrumentTimeout(other, "ABOR", "no reply")

    digitizer.abort = late
    result, _ = run(controller, config(safe_s=2.5), digitizer=digitizer)
    assert result.confirmed and not result.controller_timed_out
    assert result.elapsed_s < 1.0
    # and the same timeout raised through the controller's role (a lab's driver that names the
    # device behind it): only the valve controller's own timeout can leave a late request behind
    controller = Controller()
    controller.failures["valves"] = [InstrumentTimeout(other, "read coils", "no reply")]
    result, _ = run(controller, config(safe_s=2.5))
    assert result.confirmed and not result.controller_timed_out
    assert result.elapsed_s < 1.0


def test_a_valve_that_changes_late_is_caught_within_the_hold() -> None:
    """A late 'fill open' (a request the controller carried out after its timeout) seen during
    the hold is closed again before SAFE confirms."""
    controller = Controller()
    controller.failures["valves"] = [InstrumentTimeout(NAME, "read coils", "no reply")]
    rounds = []

    def sleep(_: float) -> None:
        rounds.append(1)
        if len(rounds) == 3:
            controller.coils["fill_valve"] = True

    result, _ = run(controller, config(safe_s=2.5), sleep=sleep)
    assert result.confirmed
    assert controller.commands.count(("fill_valve", False)) == 2
    assert controller.coils["fill_valve"] is False


def test_a_safe_result_is_frozen_and_its_defaults_claim_nothing() -> None:
    result = safe.SafeResult(True)
    assert (result.problem, result.reservoir_pressure_bar, result.valves, result.controller_timed_out,
            result.interrupt, result.elapsed_s) == (None, None, None, False, None, 0.0)
    with pytest.raises(AttributeError):
        result.confirmed = False  # type: ignore[misc]


# -- the untrusted gauge (module docstring, point 4) ------------------------------------------------------
SAFE_BUT_UNKNOWN = "the valves read back safe (fire and fill closed, vent open, pump off), but "


def reservoir_finding(value_bar: float) -> Implausible:
    """What rig/plausibility.py says of a reservoir reading read through the role (no register)."""
    finding = judge(RESERVOIR, value_bar, plausible_ranges(config())[RESERVOIR])
    assert finding is not None
    return finding


@pytest.mark.parametrize("pressure_bar", [4.07e27, -5.0, 16.5])
def test_a_reading_that_cannot_be_true_ends_safe_at_once_saying_the_pressure_is_unknown(pressure_bar) -> None:
    """The default range is -1 .. 2 x max_pressure_bar (16 bar): outside it the reading is no
    pressure at all; SAFE says so as soon as the valves read back safe, not after safe_s, and
    never guesses "fill valve stuck open?"."""
    controller = Controller(pressure_bar=pressure_bar)
    waits: list[float] = []
    result, events = run(controller, config(safe_s=2.5), sleep=waits.append)
    finding = reservoir_finding(pressure_bar)
    assert finding.message.startswith("the reservoir pressure reads ") and "which cannot be true" in finding.message
    assert not result.confirmed
    assert result.problem == f"{NAME}: {SAFE_BUT_UNKNOWN}{finding.message}: the reservoir pressure is unknown"
    assert waits == []  # at once: one round, no waiting for a vent that cannot be seen
    assert result.reservoir_pressure_bar == pressure_bar
    assert controller.commands == [("fire_valve", False), ("fill_valve", False), ("vent_valve", True),
                                   ("vacuum_pump", False)]
    (error,) = events.of(RigError)
    assert error.message == f"SAFE NOT CONFIRMED: {result.problem}"
    assert not events.of(Note)


def test_the_last_plausible_reading_is_vented_and_the_range_ends_are_plausible() -> None:
    """-1 bar (the range's low end) is below vent_done_bar and plausible: vented."""
    assert run(Controller(pressure_bar=-1.0))[0].confirmed
    assert run(Controller(pressure_bar=16.0))[0].problem.startswith(f"{NAME}: reservoir still at 16.000 bar")


def test_a_gauge_handed_in_as_untrusted_confirms_nothing() -> None:
    """CHECK's finding: a later reading that looks vented does not confirm."""
    finding = reservoir_finding(4.07e27)
    waits: list[float] = []
    result, _ = run(Controller(pressure_bar=0.01), config(safe_s=2.5), sleep=waits.append, untrusted_gauge=finding)
    assert not result.confirmed
    assert result.problem == f"{NAME}: {SAFE_BUT_UNKNOWN}{finding.message}: the reservoir pressure is unknown"
    assert waits == []  # at once, not after safe_s


def test_a_gauge_once_untrusted_stays_untrusted_when_it_later_reads_vented() -> None:
    controller = Controller(stuck={"vent_valve": False})  # the first round cannot end SAFE
    controller.pressures = [4.07e27, 4.07e27, 0.01]  # read for the interlocks, read again to judge; then vented

    def free_the_vent(_: float) -> None:
        controller.stuck = {}

    result, _ = run(controller, config(safe_s=2.5), sleep=free_the_vent)
    assert not result.confirmed
    assert result.problem == (f"{NAME}: {SAFE_BUT_UNKNOWN}{reservoir_finding(4.07e27).message}: the reservoir "
                              "pressure is unknown")
    assert result.reservoir_pressure_bar == 0.01


def test_a_reading_that_is_not_a_number_is_waited_for() -> None:
    """NaN is a gauge fault that may clear: SAFE goes on reading, and confirms once it reads vented;
    a gauge that never clears is not confirmed at safe_s, with the reading."""
    controller = Controller()
    controller.pressures = [math.nan, math.nan, 0.01]
    result, _ = run(controller)
    assert result.confirmed and result.reservoir_pressure_bar == 0.01
    result, _ = run(Controller(pressure_bar=math.nan))
    assert not result.confirmed and result.elapsed_s >= 0.3
    assert result.problem.startswith(f"{NAME}: reservoir still at nan bar after venting for 0.3 s")


def test_a_stuck_valve_and_an_untrusted_gauge_are_both_named_at_safe_s() -> None:
    result, _ = run(Controller(pressure_bar=4.07e27, stuck={"fill_valve": True}))
    assert not result.confirmed and result.elapsed_s >= 0.3
    assert result.problem == (f"{NAME}: fill valve open (commanded shut), wanted shut after 0.3 s; "
                              f"{reservoir_finding(4.07e27).message}: the reservoir pressure is unknown")


def test_after_a_controller_timeout_an_untrusted_gauge_is_said_after_the_hold() -> None:
    """The valves may still change late: SAFE keeps re-checking them for the hold (1 s here)
    before it ends on the untrusted gauge, and ends then, not at safe_s."""
    result, _ = run(Controller(pressure_bar=4.07e27), config(safe_s=4.0), controller_timed_out=True)
    assert not result.confirmed and result.controller_timed_out
    assert 1.0 <= result.elapsed_s < 3.0
    assert result.problem.startswith(f"{NAME}: {SAFE_BUT_UNKNOWN}the reservoir pressure reads 4.07e+27 bar")


def test_a_vented_reading_that_cannot_be_judged_is_not_confirmed_until_it_can() -> None:
    """The judge reads the gauge again (with its words where it can); an error there leaves the
    round unclean, and a later clean round confirms."""
    controller = Controller(pressure_bar=0.01)
    controller.failures["reservoir_pressure_bar"] = [None, InstrumentError(NAME, "read gauge", "no reply")]
    rounds = []
    result, _ = run(controller, sleep=rounds.append)
    assert result.confirmed
    assert len(rounds) == 1  # the first round was not clean: one poll, then a clean round


# -- interlock rules ------------------------------------------------------------------------------------
def readings(**kw: Any) -> RigReadings:
    base: dict[str, Any] = dict(reservoir_pressure_bar=2.0, fixture_vacuum_mbar=50.0, door_closed=True,
                                fixture_clamped=True, estop_healthy=True, amplifier_overloaded=False,
                                digitizer_state="ARMED")
    base.update(kw)
    return RigReadings(**base)


@pytest.mark.parametrize(("pressure", "setpoint", "charging", "ok", "detail"), [
    (8.0, None, False, True, "reservoir 8.000 bar"),                  # the limit itself holds
    (8.001, None, False, False, "reservoir 8.001 bar above the limit 8 bar"),
    (8.001, 9.0, True, False, "reservoir 8.001 bar above the limit 8 bar"),
    (2.05, 2.0, False, True, "reservoir 2.050 bar"),                  # set-point + tolerance holds
    (2.0501, 2.0, True, False,
     "reservoir 2.050 bar above the set-point 2 bar + 0.05 bar (fill valve not closing?)"),
    (1.95, 2.0, False, True, "reservoir 1.950 bar"),                  # set-point − tolerance holds
    (1.9499, 2.0, False, False, "reservoir 1.950 bar below the set-point 2 bar - 0.05 bar (leaking?)"),
    (0.5, 2.0, True, True, "reservoir 0.500 bar"),                    # still charging
    (math.nan, None, False, False, "reservoir gauge reads nan (not a number: check the gauge and its register)"),
])
def test_pressure_check(pressure, setpoint, charging, ok, detail) -> None:
    check = pressure_check(pressure, LIMITS, setpoint, charging)
    assert (check.code, check.ok, check.detail) == (InterlockCode.PRESSURE, ok, detail)


@pytest.mark.parametrize(("field", "value", "ok", "detail"), [
    ("door_closed", True, True, "door/guard closed"), ("door_closed", False, False, "door/guard open"),
    ("fixture_clamped", True, True, "fixture clamped"), ("fixture_clamped", False, False, "fixture not clamped"),
    ("estop_healthy", True, True, "e-stop healthy"), ("estop_healthy", False, False, "e-stop tripped"),
    ("fixture_vacuum_mbar", 100.0, True, "fixture vacuum 100.0 mbar at or below 100 mbar"),
    ("fixture_vacuum_mbar", 100.05, False, "fixture vacuum 100.0 mbar above 100 mbar"),
    ("fixture_vacuum_mbar", math.inf, False,
     "fixture vacuum gauge reads inf (not a number: check the gauge and its register)"),
    ("digitizer_state", "ARMED", True, "digitizer armed"),
    ("digitizer_state", "TRIGGERED", False, "digitizer not armed (state TRIGGERED)"),
    ("digitizer_state", None, False, "digitizer not armed (state None)"),
    ("amplifier_overloaded", False, True, "amplifier not overloaded"),
    ("amplifier_overloaded", True, False, "amplifier overloaded"),
    ("amplifier_overloaded", None, False, "amplifier overload status not read"),
])
def test_each_rule_and_its_words(field, value, ok, detail) -> None:
    name = {"door_closed": "door", "fixture_clamped": "clamp", "estop_healthy": "estop",
            "fixture_vacuum_mbar": "vacuum", "digitizer_state": "digitizer", "amplifier_overloaded": "amplifier"}[field]
    report = evaluate(readings(**{field: value}), LIMITS, (name,))
    (check,) = report.checks
    assert (check.name, check.ok, check.detail) == (name, ok, detail)
    assert report.all_ok is ok
    assert report.problems() == ([] if ok else [detail])
    assert report.failing() == ([] if ok else [InterlockCode(name)])
    assert report.hints() == ([] if ok else [InterlockCode(name).hint])


def test_a_report_keeps_the_interlocks_order_and_only_those_required() -> None:
    report = evaluate(readings(door_closed=False, digitizer_state="IDLE"), LIMITS,
                      ("digitizer", "door", "pressure"), setpoint_bar=2.0)
    assert [c.name for c in report.checks] == ["door", "pressure", "digitizer"]
    assert report.as_dict() == {"door": False, "pressure": True, "digitizer": False}
    assert report.details() == {"door": "door/guard open", "pressure": "reservoir 2.000 bar",
                                "digitizer": "digitizer not armed (state IDLE)"}
    assert report.hints() == [InterlockCode.DOOR.hint, InterlockCode.DIGITIZER.hint]
    assert not report.all_ok
    event = report.reading("ARM", idle=True)
    assert (event.state, event.reservoir_pressure_bar, event.fixture_vacuum_mbar, event.idle) == ("ARM", 2.0, 50.0, True)
    assert event.interlocks == report.as_dict() and event.details == report.details()
    assert (event.amplifier_overloaded, event.digitizer_state) == (False, "IDLE")
    assert report.reading("ARM").idle is False
    with pytest.raises(TypeError):
        report.reading("ARM", True)  # type: ignore[misc]  # idle is keyword-only
    with pytest.raises(ValueError, match=r"unknown interlock\(s\) \['doors'\]"):
        evaluate(readings(), LIMITS, ("door", "doors"))


def test_readings_and_judgements_are_frozen() -> None:
    report = evaluate(readings(), LIMITS, ("door",))
    for value, field in ((report.readings, "door_closed"), (report.checks[0], "ok"), (report, "checks")):
        with pytest.raises(AttributeError):
            setattr(value, field, False)


def test_evaluate_judges_a_charged_reservoir_unless_told_it_is_charging() -> None:
    low = readings(reservoir_pressure_bar=1.0)
    assert evaluate(low, LIMITS, ("pressure",), setpoint_bar=2.0).failing() == [InterlockCode.PRESSURE]
    assert evaluate(low, LIMITS, ("pressure",), setpoint_bar=2.0, charging=True).all_ok


def test_what_each_state_requires() -> None:
    basic = ("door", "clamp", "estop", "amplifier")
    assert REQUIRED == {"CHECK": basic, "EVACUATE": basic, "CHARGE": (*basic, "vacuum", "pressure"),
                        "ARM": INTERLOCKS, "FIRE": INTERLOCKS}
    assert INTERLOCKS == ("door", "clamp", "estop", "vacuum", "pressure", "digitizer", "amplifier")
    assert all(code.hint.endswith(".") and len(code.hint) > 20 for code in InterlockCode)
    assert len({code.hint for code in InterlockCode}) == len(InterlockCode)


def test_reading_the_instruments() -> None:
    controller = Controller(pressure_bar=3.5)
    got = controller_readings(controller)
    assert got == RigReadings(reservoir_pressure_bar=3.5, fixture_vacuum_mbar=990.0, door_closed=True,
                              fixture_clamped=False, estop_healthy=True)
    instruments = SimpleNamespace(valves=controller,
                                  amplifier=SimpleNamespace(overloaded=lambda: True),
                                  digitizer=SimpleNamespace(acquisition_state=lambda: "ARMED"))
    assert read_readings(instruments) == RigReadings(3.5, 990.0, True, False, True, True, None)
    assert read_readings(instruments, amplifier=False, digitizer=True) == RigReadings(3.5, 990.0, True, False, True,
                                                                                       None, "ARMED")
    with pytest.raises(TypeError):
        read_readings(instruments, False)  # type: ignore[misc]  # the flags are keyword-only: no bare booleans
