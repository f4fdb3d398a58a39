"""SAFE (rig/sequencer/safe.py), unit by unit.

These kill the mutants the sequencer's fault-injection tests let survive (docs/mutation-testing.md):
each branch of SAFE's confirmation, its messages and its hold after a controller timeout, and its
untrusted-gauge path, on a scripted controller (tests/rig/scripted_safe.py: a unit test of SAFE's
logic; the real protocols are tested in test_sequencer_faults.py and test_cli_safe.py). The
interlock rules are test_mutants_interlocks.py's.
"""

from __future__ import annotations

import math

import pytest

from hopkinson.drivers.errors import InstrumentError, InstrumentTimeout
from hopkinson.rig.errors import HINT_SAFE_NOT_CONFIRMED
from hopkinson.rig.events import Note, Reading, RigError, RigWarning
from hopkinson.rig.plausibility import RESERVOIR, Implausible, judge, plausible_ranges
from hopkinson.rig.sequencer import safe
from hopkinson.rig.sequencer.safe import gauge_half_count_bar, make_rig_safe, safe_hold_s
from tests.rig.scripted_safe import NAME, Controller, Digitizer, Events, config, run

# Each test here takes well under 2 s; a mutant that keeps SAFE from ever returning fails at 30 s.
pytestmark = pytest.mark.timeout(30)


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
