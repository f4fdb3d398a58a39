"""The simulated digitizer's instrument core: its state, the IEEE 488.2 common commands, the
acquisition and the transfer formats every dialect shares (drivers/sim/scpi_digitizer.py serves
it on a socket; drivers/sim/scpi_messages.py frames its messages).

- IEEE 488.2 common commands, as the standard says: *IDN?, *RST, *CLS, *ESE/*ESE?, *ESR?
  (the standard event status register: bit 0 operation complete, 2 query error, 3
  device-dependent error, 4 execution error, 5 command error; read clears), *SRE/*SRE?, *STB?
  (bit 2 error/event queue not empty, 4 message available, 5 event status summary, 6 master
  summary), *OPC (sets ESR bit 0 once the acquisition in progress is complete), *OPC? (answers
  1 once it is complete: it does not answer while the instrument is armed), *WAI (holds the
  rest of the message until then), *TST? (0: self-test passed).
- An acquisition that honours its trigger: while ARMED, the instrument polls
  `capture(settings)`. The world (drivers/sim/world.py) returns None (no shot) or the channels'
  signals in volts; given `settings.trigger_index`, it serves one record's length before the
  shot too, and the instrument keeps the record around the first real crossing of the trigger
  level, with the configured slope, on the configured source. A wrong source, level or slope
  means no capture: the instrument stays ARMED and the shot is lost, as on the real rig. The
  external input ("EXT") has nothing connected in the simulated rig.
- Channels on or off: an oscilloscope acquires only the channels that are on (displayed). Each
  dialect has its command for it and its power-on / *RST state (`power_on_channels`: the
  generic digitizer has all four on, the scopes channel 1 alone); a channel off at the capture
  (or turned off since) has no record, and each dialect answers its transfer as its instrument
  does (an empty block, an empty trace or a refusal).
- The record is kept in volts and converted at transfer to the format asked for (int8, uint8,
  int16, uint16, float32, either byte order), clipped at the format's full-scale codes (or,
  for float32, at the channel's range) as a converter clips, never wrapped.
"""

from __future__ import annotations

import copy
import re
import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hopkinson.drivers.sim.faults import FaultSet
from hopkinson.drivers.sim.scpi_messages import (
    Block,
    Call,
    Handler,
    Reply,
    SimError,
    node_matches,
    split_units,
)

CHANNELS = (1, 2, 3, 4)
SAMPLE_RATE_LIMITS_HZ = (1e3, 1e10)
RECORD_LENGTH_LIMITS = (16, 100_000_000)
RANGE_LIMITS_V = (0.001, 100.0)
OPC_POLL_S = 0.002
SIM_FORMATS = ("int8", "uint8", "int16", "uint16", "float32")

# IEEE 488.2 standard event status register bits
ESR_OPC, ESR_QYE, ESR_DDE, ESR_EXE, ESR_CME = 0x01, 0x04, 0x08, 0x10, 0x20


@dataclass
class AcquisitionSettings:
    """The acquisition settings as the instrument holds them (dialect-neutral).

    ch_range_v: full scale per channel number (the channel reads -range .. +range volts).
    trigger_source: "CH1".."CH4" or "EXT"; trigger_slope: "POS" | "NEG".
    """

    sample_rate_hz: float = 100e6
    record_length: int = 1_000_000
    pre_trigger_samples: int = 100_000
    ch_range_v: dict[int, float] = field(default_factory=lambda: {1: 1.0, 2: 10.0, 3: 1.0, 4: 10.0})
    trigger_source: str = "CH2"
    trigger_level_v: float = 0.1
    trigger_slope: str = "POS"

    def trigger_index(self, channels: dict[int, np.ndarray], first: int, last: int) -> int | None:
        """The first sample in first..last where the source crosses the level with the slope
        (the sample after the crossing), or None: no trigger."""
        if not self.trigger_source.startswith("CH"):
            return None  # nothing is connected to the external input of the simulated rig
        signal = channels.get(int(self.trigger_source[2:]))
        if signal is None:
            return None
        first = max(first, 1)
        window = np.asarray(signal[first - 1:last + 1], dtype=float)
        before, after = window[:-1], window[1:]
        level = self.trigger_level_v
        crossed = (before < level) & (after >= level) if self.trigger_slope == "POS" else \
            (before > level) & (after <= level)
        hits = np.flatnonzero(crossed)
        return first + int(hits[0]) if hits.size else None


CaptureFn = Callable[[AcquisitionSettings], "dict[int, np.ndarray] | None"]


def quantise(volts: np.ndarray, range_v: float, sample_format: str,
             reserved_lowest: bool = False) -> tuple[np.ndarray, float, float]:
    """(codes, scale_v, zero_code): volts = (code - zero_code) * scale_v, clipped to the
    format's rails (float32: to ±range_v), never wrapped. `reserved_lowest`: the format's
    lowest code means "no data" (a hole), so the converter clips one code above it."""
    if sample_format == "float32":
        return np.clip(volts, -range_v, range_v).astype(np.float32), 1.0, 0.0
    info = np.iinfo(np.dtype(sample_format))
    half = (int(info.max) - int(info.min)) // 2  # 127 or 32767 codes per range
    zero = 0 if info.min < 0 else half + 1
    scale = range_v / half
    low = int(info.min) + (1 if reserved_lowest else 0)
    codes = np.clip(np.rint(volts / scale) + zero, low, info.max).astype(sample_format)
    return codes, scale, float(zero)


class SimDigitizer:
    """A simulated digitizer's state, IEEE 488.2 core and acquisition (module docstring).

    Dialects subclass it: `table()` lists their commands; `record_error` reports an error
    their way; `identity` names them. Shared by all connections; `lock` guards the state.
    """

    identity = "Hopkinson-Sim,SIMDIG-4CH,SIM0001,1.0"
    channel_names: dict[str, int] = {"CH1": 1, "CH2": 2, "CH3": 3, "CH4": 4}
    power_on_channels: tuple[int, ...] = CHANNELS  # on after power-on and *RST
    hole_code = False  # True: the format's lowest code is a hole, the converter clips above it

    def __init__(self, capture: CaptureFn, faults: FaultSet) -> None:
        self._capture = capture
        self.faults = faults
        self.lock = threading.RLock()
        self._table = self.table()
        self.esr, self.ese, self.sre = 0, 0, 0  # status: kept by *RST, cleared by *CLS
        self.errors: list[tuple[int, str]] = []
        self.opc_armed = False
        self.reset()

    # -- state ---------------------------------------------------------------------------
    def reset(self) -> None:
        """*RST: settings to their defaults, acquisition stopped (status kept, as *RST does)."""
        with self.lock:
            self.settings = AcquisitionSettings()
            self.state = "IDLE"
            self.volts: dict[int, np.ndarray] = {}
            self.acquisitions = 0  # completed since the last arm
            self.sample_format, self.byte_order = "int16", "little"
            self.waveform_source = 1
            self._encoded: dict[tuple[int, str, str], tuple[bytes, float, float]] = {}
            self.channel_on = {n: n in self.power_on_channels for n in CHANNELS}
            self.acquired: frozenset[int] = frozenset()  # the channels on at the last capture

    def table(self) -> list[tuple[tuple[str, ...], Handler]]:
        """The dialect's commands: (header node patterns, handler)."""
        return []

    @staticmethod
    def esr_bit(code: int) -> int:
        """The standard event status bit of an error's class (-1xx command, -2xx execution, ...)."""
        return {1: ESR_CME, 2: ESR_EXE, 3: ESR_DDE, 4: ESR_QYE}.get(abs(code) // 100, ESR_DDE)

    def record_error(self, code: int, message: str) -> None:
        """Report an error: set the event status bit of its class and queue it."""
        self.esr |= self.esr_bit(code)
        if len(self.errors) < 32:
            self.errors.append((code, message.replace('"', "'")))

    def pending(self) -> bool:
        """An operation in progress (the armed acquisition): *OPC?, *OPC and *WAI wait for it."""
        return self.state == "ARMED"

    # -- acquisition ---------------------------------------------------------------------
    def arm(self) -> None:
        self.volts, self._encoded, self.state, self.acquisitions = {}, {}, "ARMED", 0

    def stop(self) -> None:
        self.state = "IDLE" if self.state == "ARMED" else self.state

    def poll_capture(self) -> None:
        """While ARMED, ask the world whether a triggered record is there."""
        if self.state != "ARMED":
            return
        try:
            volts = self._capture(copy.deepcopy(self.settings))
        except Exception as exc:  # the world failed: report it as the instrument would
            raise SimError(-240, f"Hardware error; simulated capture failed: {exc}") from None
        if volts is None:
            return
        n = self.settings.record_length
        record = {}
        for ch, data in volts.items():  # a channel the world leaves out has nothing connected: 0 V
            record[ch] = np.asarray(data, dtype=float)
            if ch not in CHANNELS or record[ch].shape != (n,):
                raise SimError(-240, f"simulated capture gave {record[ch].shape} samples on channel {ch}, "
                                     f"expected {n} on one of {CHANNELS}")
        self.acquired = frozenset(ch for ch, on in self.channel_on.items() if on)
        record = {ch: data for ch, data in record.items() if ch in self.acquired}
        self.volts, self._encoded, self.state = record, {}, "TRIGGERED"
        self.acquisitions += 1
        if self.opc_armed:
            self.esr |= ESR_OPC
            self.opc_armed = False

    def encoded(self, channel: int) -> tuple[memoryview, float, float] | None:
        """(payload bytes, scale_v, zero_code) of a channel in the current transfer format;
        None without a record (none taken, or the channel off at the capture or since)."""
        if not self.has_record(channel):
            return None
        key = (channel, self.sample_format, self.byte_order)
        if key not in self._encoded:
            volts = self.volts.get(channel)
            if volts is None:
                volts = np.zeros(self.settings.record_length)
            codes, scale, zero = quantise(volts, self.settings.ch_range_v[channel], self.sample_format,
                                          self.hole_code)
            order = "<" if self.byte_order == "little" else ">"
            codes = np.ascontiguousarray(codes.astype(codes.dtype.newbyteorder(order), copy=False))
            self._encoded[key] = (memoryview(codes).cast("B"), scale, zero)
        return self._encoded[key]

    def has_record(self, channel: int) -> bool:
        """A record was taken with the channel on, and it is on still."""
        return self.state == "TRIGGERED" and channel in self.acquired and self.channel_on[channel]

    def off_channel(self, channel: int) -> bool:
        """A record was taken but this channel has none because it is (or was) off."""
        return self.state == "TRIGGERED" and not self.has_record(channel)

    def channel_state(self, c: Call, on: str = "1", off: str = "0") -> Reply:
        """A channel's on/off command (ON|OFF|1|0) or query (answered `on` or `off`)."""
        channel = self.channel(c.suffix)
        if c.query:
            return on if self.channel_on[channel] else off
        self.channel_on[channel] = self.choice(c.arg, {"ON": "1", "1": "1", "OFF": "0", "0": "0"}) == "1"
        return None

    # -- the interpreter -------------------------------------------------------------------
    def execute(self, message: str, stopping: threading.Event) -> list[str | Block]:
        """Run one message; the replies of its queries in order."""
        replies: list[str | Block] = []
        for unit in split_units(message):
            if unit.upper() in ("*OPC?", "*WAI") and not self._wait_complete(stopping):
                return replies  # the server stops: nothing more is answered
            with self.lock:
                try:
                    self.poll_capture()  # the instrument acquires on its own, whatever is asked
                    reply = self._execute_unit(unit, replies)
                except SimError as exc:
                    self.record_error(exc.code, f"{exc.message}; {unit}")
                    continue
            if reply is not None:
                replies.append(reply)
        return replies

    def _wait_complete(self, stopping: threading.Event) -> bool:
        """Hold until no operation is pending (polling the acquisition); False if stopping."""
        while True:
            with self.lock:
                try:
                    self.poll_capture()
                except SimError as exc:
                    self.record_error(exc.code, exc.message)
                    self.state = "IDLE"
                if not self.pending():
                    return True
            if stopping.wait(OPC_POLL_S):
                return False

    def _execute_unit(self, unit: str, replies: list[str | Block]) -> Reply:
        header, _, arg = unit.partition(" ")
        arg = arg.strip()
        query = header.endswith("?")
        header = header.rstrip("?").lstrip(":")
        if header.startswith("*"):
            return self._common(header.upper(), query, arg, replies)
        nodes = header.split(":")
        for patterns, handler in self._table:
            if len(patterns) != len(nodes):
                continue
            suffixes: list[int | None] = []
            for node, pattern in zip(nodes, patterns, strict=True):
                ok, suffix = node_matches(node, pattern)
                if not ok:
                    break
                suffixes.append(suffix)
            else:
                numbered = tuple(x for x in suffixes if x is not None)
                return handler(Call(numbered, query, arg, patterns, tuple(suffixes)))
        raise SimError(-113, "Undefined header")

    def _common(self, header: str, query: bool, arg: str, replies: list[str | Block]) -> Reply:
        if header == "*IDN" and query:
            return self.identity
        if header == "*RST" and not query:
            self.reset()
            return None
        if header == "*CLS" and not query:
            self.esr, self.errors, self.opc_armed = 0, [], False
            self.clear_status()
            return None
        if header == "*ESR" and query:
            value, self.esr = self.esr, 0
            return str(value)
        if header in ("*ESE", "*SRE"):
            attr = header[1:].lower()
            if query:
                return str(getattr(self, attr))
            setattr(self, attr, int(self.number(arg)) & 0xFF)
            return None
        if header == "*STB" and query:
            return str(self.status_byte(bool(replies)))
        if header == "*OPC":
            if query:
                return "1"  # execute() held it until nothing was pending
            if self.pending():
                self.opc_armed = True
            else:
                self.esr |= ESR_OPC
            return None
        if header == "*WAI" and not query:
            return None  # execute() held the message until nothing was pending
        if header == "*TST" and query:
            return "0"
        raise SimError(-113, "Undefined header")

    def clear_status(self) -> None:
        """*CLS of a dialect's own status registers (override)."""

    # -- the SCPI error queue (:SYSTem:ERRor?, :SYSTem:ERRor:COUNt?) --------------------------
    signed_numbers = False  # Keysight answers "+0"

    def system_error(self, c: Call) -> Reply:
        """The oldest error, '<code>,"<text>"' (0,"No error" when there is none)."""
        c.query_only()
        code, message = self.errors.pop(0) if self.errors else (0, "No error")
        return f'{code:+d},"{message}"' if self.signed_numbers else f'{code},"{message}"'

    def system_error_count(self, c: Call) -> Reply:
        c.query_only()
        return f"{len(self.errors):+d}" if self.signed_numbers else str(len(self.errors))

    # -- settings a simulator keeps fixed --------------------------------------------------
    def zero_only(self, c: Call, reply: str) -> Reply:
        """A channel's offset or position: only 0 is simulated."""
        self.channel(c.suffix)
        if c.query:
            return reply
        if self.number(c.arg) != 0.0:
            raise SimError(-221, "Settings conflict; only 0 is simulated")
        return None

    @staticmethod
    def edge_only(c: Call) -> Reply:
        """The trigger type: only an edge trigger is simulated."""
        if c.query:
            return "EDGE"
        SimDigitizer.choice(c.arg, ("EDGE",))
        return None

    def status_byte(self, message_available: bool) -> int:
        """IEEE 488.2 status byte: bit 2 queue not empty, 4 MAV, 5 ESB, 6 MSS."""
        stb = (0x04 if self.errors else 0) | (0x10 if message_available else 0) | (0x20 if self.esr & self.ese else 0)
        return stb | (0x40 if stb & self.sre else 0)

    # -- parameter helpers ---------------------------------------------------------------
    @staticmethod
    def number(arg: str) -> float:
        """A numeric parameter (an optional unit suffix such as V, S or PCT is allowed)."""
        if not arg:
            raise SimError(-109, "Missing parameter")
        m = re.fullmatch(r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z%]*)", arg.strip())
        if m is None:
            raise SimError(-104, "Data type error")
        value = float(m.group(1))
        if not np.isfinite(value):
            raise SimError(-224, "Illegal parameter value")
        return value

    def integer(self, arg: str) -> int:
        value = self.number(arg)
        if value != int(value):
            raise SimError(-224, "Illegal parameter value")
        return int(value)

    @staticmethod
    def choice(arg: str, choices: dict[str, str] | tuple[str, ...]) -> str:
        """A keyword parameter: one of `choices` (or a key of the mapping, by any form)."""
        if not arg:
            raise SimError(-109, "Missing parameter")
        options = choices if isinstance(choices, dict) else {c: c for c in choices}
        for spelling, value in options.items():
            ok, _ = node_matches(arg.strip(), spelling)
            if ok:
                return value
        raise SimError(-224, "Illegal parameter value")

    @staticmethod
    def in_range(value: float, limits: tuple[float, float]) -> None:
        if not limits[0] <= value <= limits[1]:
            raise SimError(-222, "Data out of range")

    def not_while_armed(self) -> None:
        if self.state == "ARMED":
            raise SimError(-221, "Settings conflict; acquisition armed")

    def channel(self, number: int) -> int:
        if number not in CHANNELS:
            raise SimError(-114, "Header suffix out of range")
        return number

    # shared setters (each dialect converts its own units first)
    def set_sample_rate(self, value: float) -> None:
        self.in_range(value, SAMPLE_RATE_LIMITS_HZ)
        self.not_while_armed()
        self.settings.sample_rate_hz = value

    def set_record_length(self, value: int) -> None:
        self.in_range(value, RECORD_LENGTH_LIMITS)
        self.not_while_armed()
        self.settings.record_length = value
        self.settings.pre_trigger_samples = min(self.settings.pre_trigger_samples, value - 1)

    def set_pre_trigger(self, samples: int) -> None:
        if not 0 <= samples < self.settings.record_length:
            raise SimError(-221, "Settings conflict; pre-trigger must be below the record length")
        self.not_while_armed()
        self.settings.pre_trigger_samples = samples

    def set_range(self, channel: int, range_v: float) -> None:
        self.in_range(range_v, RANGE_LIMITS_V)
        self.not_while_armed()
        self.settings.ch_range_v[self.channel(channel)] = range_v

    def set_trigger(self, *, source: str | None = None, level_v: float | None = None, slope: str | None = None) -> None:
        self.not_while_armed()
        if level_v is not None:
            self.in_range(abs(level_v), (0.0, RANGE_LIMITS_V[1]))
            self.settings.trigger_level_v = level_v
        if source is not None:
            self.settings.trigger_source = source
        if slope is not None:
            self.settings.trigger_slope = slope

