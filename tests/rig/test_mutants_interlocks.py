"""The interlock rules (rig/interlocks.py), every rule at its bounds, and reading them from the
instruments (a scripted controller, tests/rig/scripted_safe.py).

These kill the mutants the sequencer's fault-injection tests let survive (docs/mutation-testing.md);
SAFE's own branches are test_mutants_safe.py's.
"""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import pytest

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
from tests.rig.scripted_safe import LIMITS, Controller

# Each test here takes well under 2 s; a mutant that hangs fails at 30 s.
pytestmark = pytest.mark.timeout(30)


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
