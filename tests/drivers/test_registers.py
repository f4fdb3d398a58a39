"""Register packing (drivers/registers.py) against hand-made words, and against the simulator's
independent packing (drivers/sim/controller_map.py)."""

from __future__ import annotations

import math
import struct

import pytest

from hopkinson.drivers.registers import (
    CoilMap,
    Register,
    RegisterMap,
    RegisterRangeError,
    contiguous_runs,
)
from hopkinson.drivers.sim.controller_map import Point


def words_of(fmt: str, value: float) -> list[int]:
    """Big-endian words of a struct format (the Modicon register order), by hand."""
    data = struct.pack(">" + fmt, value)
    return [data[i] << 8 | data[i + 1] for i in range(0, len(data), 2)]


@pytest.mark.parametrize(
    ("register", "value", "words"),
    [
        (Register(0, "uint16"), 40000, [40000]),
        (Register(0, "int16"), -2, [0xFFFE]),
        (Register(0, "int32"), -70000, words_of("i", -70000)),
        (Register(0, "int32", "little"), -70000, words_of("i", -70000)[::-1]),
        (Register(0, "uint32"), 70000, [0x0001, 0x1170]),
        (Register(0, "uint32", "little"), 70000, [0x1170, 0x0001]),
        (Register(0, "float32"), 1.5, [0x3FC0, 0x0000]),
        (Register(0, "float32", "little"), 1.5, [0x0000, 0x3FC0]),
        (Register(0, "uint16", scale=0.001), 4.321, [4321]),
        (Register(0, "int16", scale=0.01, offset=-1.0), 0.5, [150]),
        (Register(0, "uint16", scale=-0.5), -10.0, [20]),
    ],
)
def test_encode_and_decode_match_hand_made_words(register: Register, value: float, words: list[int]) -> None:
    assert register.encode(value) == words
    assert register.decode(words) == pytest.approx(value, rel=1e-7)


@pytest.mark.parametrize("point", [Point(0, t, o, s, f) for t in ("int16", "uint16", "int32", "uint32", "float32")
                                   for o in ("big", "little") for s, f in ((1.0, 0.0), (0.01, -3.0))])
def test_driver_and_simulator_pack_alike(point: Point) -> None:
    register = Register(point.address, point.type, point.word_order, point.scale, point.offset)
    low, high = register.value_range()
    for value in (max(low, -1.0), 0.0, 12.25, min(high, 60000.0)):
        if not register.holds(value):
            continue
        assert register.encode(value) == point.pack(value)
        assert register.decode(point.pack(value)) == pytest.approx(point.unpack(register.encode(value)), rel=1e-6)


@pytest.mark.parametrize(
    ("register", "value", "message"),
    [
        (Register(0, "uint16", scale=0.001), 65.536, r"65.536 outside what the uint16 register holds \(0 .. 65.535\)"),
        (Register(0, "uint16"), -1.0, "outside"),
        (Register(0, "int16"), 40000, r"\(-32768 .. 32767\)"),
        (Register(0, "uint32"), 2.0**32, "outside"),
        (Register(0, "float32"), 1e39, "outside"),
        (Register(0, "float32"), math.nan, "not a finite number"),
        (Register(0, "int32"), math.inf, "not a finite number"),
    ],
)
def test_a_value_the_register_cannot_hold_is_refused_never_wrapped(register: Register, value: float,
                                                                   message: str) -> None:
    with pytest.raises(RegisterRangeError, match=message):
        register.encode(value)


def test_register_properties_and_checks() -> None:
    pressure = Register(7, "int32", scale=1e-4, offset=-1.0)
    assert (pressure.words, list(pressure.addresses), pressure.resolution) == (2, [7, 8], 1e-4)
    assert pressure.value_range() == pytest.approx((-(2**31) * 1e-4 - 1.0, (2**31 - 1) * 1e-4 - 1.0))
    assert Register(0, "float32").resolution == 0.0 and not Register().present
    for bad in ({"type": "int64"}, {"word_order": "middle"}, {"scale": 0.0}, {"offset": math.nan}):
        with pytest.raises(ValueError):
            Register(0, **bad)  # type: ignore[arg-type]


def test_contiguous_runs_split_a_map_with_gaps() -> None:
    assert contiguous_runs([10, 0, 2, 1, 8, 9, 2]) == [(0, 3), (8, 3)]
    assert contiguous_runs([]) == []


def test_overlapping_values_are_found() -> None:
    from hopkinson.drivers.registers import InputRegisterMap

    ok = RegisterMap()
    assert ok.overlaps() == []
    clash = RegisterMap(input_registers=InputRegisterMap(fixture_vacuum=Register(4, "float32")))
    assert clash.overlaps() == ["input_registers.fixture_vacuum and input_registers.fire_pulse_count both use address 4",
                                "input_registers.fixture_vacuum and input_registers.fire_pulse_count both use address 5"]


# -- the other readings of the same words (for rig/plausibility.py's likely cause) ----------------------
def test_reinterpretations_try_the_other_word_order_first_then_the_other_types() -> None:
    register = Register(5, "float32", "big", scale=0.5)
    others = register.reinterpretations()
    assert others[0] == Register(5, "float32", "little", scale=0.5)  # the classic mistake first
    assert set(others[1:]) == {Register(5, t, o, scale=0.5) for t in ("int32", "uint32") for o in ("big", "little")}
    assert Register(0, "uint16").reinterpretations() == [Register(0, "int16")]
    assert Register(0, "int16", scale=0.1).reinterpretations() == [Register(0, "uint16", scale=0.1)]
    words = words_of("f", 2.0)[::-1]  # low word first, as a PLC that sends it so
    assert Register(0, "float32", "little").decode(words) == 2.0
    assert Register(0, "float32", "big").decode(words) == pytest.approx(2.2958874e-41, rel=1e-6)
    assert Register(0, "float32").changes_from(Register(0, "float32", "little")) == 'word_order = "big"'
    assert Register(0, "int32", "little").changes_from(Register(0, "float32")) == \
        'type = "int32", word_order = "little"'


def test_a_float_too_close_to_zero_is_no_reading_but_zero_is() -> None:
    register = Register(0, "float32")
    assert register.implausibly_small(words_of("f", 2.0)[::-1])  # 2.3e-41
    assert register.implausibly_small(words_of("f", 5e-10))
    assert not register.implausibly_small([0, 0])
    assert not register.implausibly_small(words_of("f", 2e-9))  # a tiny but possible reading
    assert not Register(0, "uint32").implausibly_small([0, 1])  # integers are judged by their range
    assert register.raw(words_of("f", 1.5)) == 1.5


def test_describe_says_where_and_how_a_value_is_read() -> None:
    assert Register(1, "float32", "little").describe("input_registers") == "input registers 1..2, float32 little"
    assert Register(0, "uint16", scale=0.001, offset=-1.0).describe("holding_registers") == \
        "holding registers 0, uint16, x0.001 -1"


def test_the_fire_command_entries_are_optional_and_never_read_as_actuators() -> None:
    default = RegisterMap()
    assert default.coils.fire_command == -1 and default.holding_registers.fire_command == -1
    assert "fire_command" not in default.blocks()["coils"]  # absent: neither read nor checked
    mapped = RegisterMap(coils=CoilMap(fire_command=6))
    assert mapped.blocks()["coils"]["fire_command"] == 6
    assert RegisterMap(coils=CoilMap(fire_command=3)).overlaps() == [
        "coils.vacuum_pump and coils.fire_command both use address 3"]
