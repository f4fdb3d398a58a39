"""Digitizer dialects: each vendor's command set and reply parsing, one class per dialect.

The driver (drivers/digitizer.py) owns the VISA session (bounded reads, deadlines, tracing,
errors naming the instrument); a dialect owns the words. It gets a `ScpiLink` to talk through
and the configured `DigitizerSettings` as context (which channels, record length, trigger),
and does each job the way its instruments want it:

    prepare(link)                        once per session: reply format, waveform encoding
    apply(link, settings)                send every acquisition setting (refusals raise)
    read_settings(link, context)         read them back as DigitizerSettings
    arm(link) / abort(link) / state(link) -> "IDLE" | "ARMED" | "TRIGGERED"
    fetch(link, channel, context)        one channel's record as a Waveform

Dialects here: `GenericScpiDialect` (below; the project's own SCPI digitizer),
`KeysightDialect` (drivers/digitizer_keysight.py), `TektronixDialect`
(drivers/digitizer_tektronix.py), `LeCroyDialect` (drivers/digitizer_lecroy.py). A lab's own is a
subclass of `DigitizerDialect` in its own package, named in rig.toml as
`[digitizer] dialect = "package.module:Class"` (see `resolve_dialect`).

A dialect raises `DialectError` (with the command and the reply); the driver turns it into an
InstrumentError naming the instrument. The transfer format (`TransferFormat`: int8, uint8,
int16, uint16 or float32, little or big endian) is the dialect's constructor argument; each
dialect lists the formats its instruments can send.

Generic SCPI (`GenericScpiDialect`, the simulator drivers/sim/digitizer_generic.py's dialect):
    :ACQuire:SRATe/POINts/PRETrigger (samples), :CHANnel<n>:RANGe (full scale, ±V),
    :CHANnel<n>:DISPlay ON|OFF | ? (1|0: a channel that is off is not acquired),
    :TRIGger:SOURce CH<n>|EXT, :TRIGger:LEVel, :TRIGger:SLOPe POS|NEG, :SINGle, :ABORt,
    :ACQuire:STATe? (IDLE|ARMED|TRIGGERED), :WAVeform:SOURce, :WAVeform:FORMat
    INT8|UINT8|INT16|UINT16|FLOAT32, :WAVeform:BYTeorder LSBF|MSBF, :WAVeform:PREamble?
    ("<format>,<order>,<points>,<x_increment_s>,<trigger_index>,<y_scale_v>,<y_offset_v>"),
    :WAVeform:DATA? (IEEE 488.2 block), errors from :SYSTem:ERRor?.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from hopkinson.drivers.digitizer_settings import DigitizerSettings
from hopkinson.drivers.digitizer_waveform import (
    BYTE_ORDERS,
    SAMPLE_FORMATS,
    SampleFormatError,
    Waveform,
    decode_samples,
    integer_rails,
    sample_dtype,
)

ACQUISITION_STATES = ("IDLE", "ARMED", "TRIGGERED")
BLOCK_SLACK_BYTES = 65536  # a block may carry this much beyond its samples (descriptors, text)


class DialectError(Exception):
    """A reply the dialect cannot use, or a command the instrument refused."""

    def __init__(self, command: str, problem: str, reply: str | bytes = "") -> None:
        super().__init__(problem)
        self.command = command
        self.problem = problem
        self.reply = reply


class ReplyFormatError(DialectError):
    """A reply that does not parse."""


class CommandRefused(DialectError):
    """The instrument reported an error for a command."""


class ChannelOff(DialectError):
    """A transfer came back empty because its channel is off (not acquired)."""

    def __init__(self, command: str, channel: str, reply: str | bytes = "") -> None:
        super().__init__(command, f"{channel} is off on the instrument, and a channel that is off is not "
                                  f"acquired: turn {channel} on (the rig turns on every channel it records at "
                                  "ARM and checks them before FIRE: another program or the front panel turned "
                                  "it off since)", reply)
        self.channel = channel


class ScpiLink(Protocol):
    """What a dialect talks through (the driver's VISA session). Every call is bounded in
    size and time and raises InstrumentError on a transport failure."""

    def write(self, command: str) -> None: ...

    def query(self, command: str) -> str: ...

    def query_block(self, command: str, max_bytes: int, header_max: int = 0) -> tuple[str, memoryview]:
        """Send `command`; read one IEEE 488.2 definite-length block of at most `max_bytes`
        (and the read terminator after it). `header_max` > 0 allows that many bytes of text
        (a response header) before the '#'; it is returned with the payload."""
        ...


@dataclass(frozen=True)
class TransferFormat:
    """How waveform samples travel: sample format and byte order."""

    sample_format: str = "int16"
    byte_order: str = "little"


class DigitizerDialect:
    """Base of every dialect: naming, the transfer format and shared parsing helpers.

    Subclasses set the class attributes and implement the job methods (module docstring).
    """

    name: ClassVar[str] = ""
    channel_names: ClassVar[tuple[str, ...]] = ()
    external_trigger: ClassVar[str] = "EXT"
    sample_formats: ClassVar[tuple[str, ...]] = SAMPLE_FORMATS
    identity_query: ClassVar[str] = "*IDN?"
    separator: ClassVar[str] = ";"

    def __init__(self, transfer: TransferFormat | None = None) -> None:
        self.transfer = transfer or TransferFormat()
        fmt, order = self.transfer.sample_format, self.transfer.byte_order
        if fmt not in self.sample_formats:
            raise ValueError(f"the {self.name} dialect cannot transfer {fmt!r} samples "
                             f"(it can: {', '.join(self.sample_formats)})")
        if order not in BYTE_ORDERS:
            raise ValueError(f"byte order must be little or big, got {order!r}")

    # -- naming ------------------------------------------------------------------------
    def channel_name(self, name: str) -> str:
        """The instrument's spelling of a channel name; ValueError listing the valid ones."""
        canonical = self._canonical_channel(name.strip().upper()) if isinstance(name, str) else None
        if canonical not in self.channel_names:
            raise ValueError(f"{name!r} is not a channel of a {self.name} digitizer "
                             f"(channels: {', '.join(self.channel_names)})")
        return canonical

    def trigger_source_name(self, name: str) -> str:
        """A channel name or the external trigger input, as the instrument spells it."""
        text = name.strip().upper() if isinstance(name, str) else ""
        if text in ("EXT", "EXTERNAL", self.external_trigger):
            return self.external_trigger
        try:
            return self.channel_name(name)
        except ValueError:
            raise ValueError(f"{name!r} is not a trigger source of a {self.name} digitizer (sources: "
                             f"{', '.join(self.channel_names + (self.external_trigger,))})") from None

    channel_prefix: ClassVar[str] = "CH"  # "CH" + number is the instrument's channel name

    def _canonical_channel(self, text: str) -> str | None:
        """The instrument's spelling of "1", "CH1", "CHAN1", "CHANNEL1" or "C1"."""
        match = re.fullmatch(r"(?:C|CH|CHAN|CHANNEL)?([1-9])", text)
        return f"{self.channel_prefix}{match.group(1)}" if match else text

    def channel_number(self, channel: str) -> int:
        """1 for "CH1"/"CHAN1"/"C1"."""
        return int(re.sub(r"\D", "", channel))

    def join(self, *units: str) -> str:
        """Several message units as one message (one round trip)."""
        return self.separator.join(units)

    # -- channels on or off ---------------------------------------------------------------------
    # An oscilloscope acquires only the channels that are on (displayed): after power-on or *RST
    # most have channel 1 alone on. A dialect whose instruments have that notion names its
    # command and query; `apply` turns on every channel the rig records and `read_settings`
    # reads their states back (DigitizerSettings.channels_on), which ARM compares before FIRE.

    def on_command(self, channel: str) -> str | None:
        """The command that turns `channel` on; None where the instruments record every channel."""
        return None

    def on_query(self, channel: str) -> str | None:
        """The query of `channel`'s on/off state (replies ON/OFF or 1/0); None as on_command."""
        return None

    def recorded_channels(self, settings: DigitizerSettings) -> tuple[str, ...]:
        """The channels the rig records (those with a range) and the trigger source's channel."""
        channels = list(settings.ranges_v)
        if settings.trigger_source != self.external_trigger and settings.trigger_source not in channels:
            channels.append(settings.trigger_source)
        return tuple(channels)

    def turn_on_units(self, settings: DigitizerSettings) -> list[str]:
        """The commands that turn on every recorded channel (empty for a dialect without them)."""
        return [unit for ch in self.recorded_channels(settings) if (unit := self.on_command(ch))]

    def read_channels_on(self, link: ScpiLink, channels: Sequence[str]) -> dict[str, bool] | None:
        """Each channel's on/off state, in one message; None for a dialect without the notion."""
        queries = [self.on_query(ch) for ch in channels]
        if not channels or any(q is None for q in queries):
            return None
        units = [q for q in queries if q is not None]
        command = self.join(*units)
        fields = self.query_fields(link, units)
        return {ch: self.on_state(command, text) for ch, text in zip(channels, fields, strict=True)}

    @staticmethod
    def on_state(command: str, text: str) -> bool:
        """ON/1 -> True, OFF/0 -> False (a response header before the value is allowed)."""
        words = text.strip().split()
        word = words[-1].upper() if words else ""
        if word in ("1", "ON"):
            return True
        if word in ("0", "OFF"):
            return False
        raise ReplyFormatError(command, f"expected a channel state ON/OFF or 1/0, got {text.strip()!r}", text)

    def with_channels_on(self, link: ScpiLink, settings: DigitizerSettings,
                         context: DigitizerSettings) -> DigitizerSettings:
        """Read-back settings completed with the recorded channels' on/off states."""
        return settings.with_changes(channels_on=self.read_channels_on(link, self.recorded_channels(context)))

    def refuse_if_off(self, link: ScpiLink, channel: str, command: str, reply: str | bytes) -> None:
        """Raise ChannelOff when `channel` is off (called when a transfer came back empty)."""
        states = self.read_channels_on(link, (channel,))
        if states is not None and not states[channel]:
            raise ChannelOff(command, channel, reply)

    # -- the jobs (subclasses implement) ---------------------------------------------------
    def prepare(self, link: ScpiLink) -> None:
        raise NotImplementedError

    def apply(self, link: ScpiLink, settings: DigitizerSettings) -> None:
        raise NotImplementedError

    def read_settings(self, link: ScpiLink, context: DigitizerSettings) -> DigitizerSettings:
        raise NotImplementedError

    def arm(self, link: ScpiLink) -> None:
        raise NotImplementedError

    def abort(self, link: ScpiLink) -> None:
        raise NotImplementedError

    def state(self, link: ScpiLink) -> str:
        raise NotImplementedError

    def fetch(self, link: ScpiLink, channel: str, context: DigitizerSettings) -> Waveform:
        raise NotImplementedError

    # -- helpers for subclasses --------------------------------------------------------------
    _completed = False  # an acquisition seen completed since the last arm or stop (latched_state)

    def latched_state(self, link: ScpiLink, run_query: str, event_query: str, armed: tuple[str, ...],
                      stopped: str, completed: int) -> str:
        """The state from a run-mode query and an event register that reading clears: the
        instrument says it is armed (a word in `armed`) or `stopped`; the register's
        `completed` bit, once seen, tells a stop after an acquisition from one without."""
        command = self.join(run_query, event_query)
        mode, register = self.query_fields(link, [run_query, event_query])
        if self.integer(command, register) & completed:
            self._completed = True
        mode = mode.upper()
        if mode in armed:
            return "ARMED"
        if mode == stopped:
            return "TRIGGERED" if self._completed else "IDLE"
        raise ReplyFormatError(command, f"unknown run state {mode!r}", self.join(mode, register))

    def forget_completion(self) -> None:
        """A new arm or a stop: no acquisition completed since."""
        self._completed = False

    def query_fields(self, link: ScpiLink, units: Sequence[str], count: int | None = None) -> list[str]:
        """Send the query units in one message; their replies, split at the separator."""
        command = self.join(*units)
        reply = link.query(command)
        fields = split_outside_quotes(reply, self.separator)
        expected = len(units) if count is None else count
        if len(fields) != expected:
            raise ReplyFormatError(command, f"expected {expected} replies, got {len(fields)}", reply)
        return fields

    @staticmethod
    def number(command: str, text: str, reply: str = "") -> float:
        """A numeric reply field (NR1/NR2/NR3, optional unit suffix such as "V" or "S")."""
        match = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*[A-Za-z%]*\s*", text)
        if match is None:
            raise ReplyFormatError(command, f"expected a number, got {text.strip()!r}", reply or text)
        return float(match.group(1))

    def integer(self, command: str, text: str, reply: str = "") -> int:
        value = self.number(command, text, reply)
        if value != int(value):
            raise ReplyFormatError(command, f"expected an integer, got {text.strip()!r}", reply or text)
        return int(value)

    def waveform(self, command: str, channel: str, payload: memoryview, *, points: int, dtype: object,
                 scale_v: float, offset_v: float, sample_interval_s: float, trigger_index: int,
                 range_v: float | None = None, code_range: tuple[float, float] | None = None) -> Waveform:
        """Decode the samples and build the Waveform (full scale: `code_range` where the
        instrument clips at codes of its own, else the format's, or for float samples the
        channel's range)."""
        try:
            codes = decode_samples(payload, dtype, points)  # type: ignore[arg-type]
        except SampleFormatError as exc:
            raise ReplyFormatError(command, str(exc)) from None
        if codes.dtype.kind == "f":
            if range_v is None:
                raise ReplyFormatError(command, "float samples need the channel's range for their full scale")
            rails = sorted(((-range_v - offset_v) / scale_v, (range_v - offset_v) / scale_v))
            code_range = (rails[0], rails[1])
        elif code_range is None:
            code_range = integer_rails(codes.dtype)
        codes.flags.writeable = False
        return Waveform(channel=channel, codes=codes, scale_v=scale_v, offset_v=offset_v,
                        sample_interval_s=sample_interval_s, trigger_index=trigger_index,
                        code_range=code_range)

    def fetch_samples(self, link: ScpiLink, data_query: str, channel: str, context: DigitizerSettings, *,
                      preamble: tuple[str, str], points: int, dtype: object, scale_v: float, offset_v: float,
                      sample_interval_s: float, trigger_index: int, range_v: float | None = None,
                      code_range: tuple[float, float] | None = None) -> Waveform:
        """Check the preamble's values, read the data block and build the Waveform.
        preamble: (the command that asked for it, its reply), for errors."""
        command, reply = preamble
        check_preamble(command, reply, points=points, interval_s=sample_interval_s, scale_v=scale_v,
                       offset_v=offset_v)
        if points == 0:
            self.refuse_if_off(link, channel, command, reply)
            raise ReplyFormatError(command, f"no acquired record on {channel}", reply)
        check_points(command, reply, points, context)
        itemsize = np.dtype(dtype).itemsize  # type: ignore[call-overload]
        _, payload = link.query_block(data_query, self.block_limit(context, points, itemsize))
        if len(payload) == 0:  # an empty block: a scope answers so for a channel that is off
            self.refuse_if_off(link, channel, data_query, bytes(payload))
        return self.waveform(data_query, channel, payload, points=points, dtype=dtype, scale_v=scale_v,
                             offset_v=offset_v, sample_interval_s=sample_interval_s, trigger_index=trigger_index,
                             range_v=range_v, code_range=code_range)

    @staticmethod
    def block_limit(context: DigitizerSettings, points: int, itemsize: int) -> int:
        """Largest block a fetch accepts: the announced samples plus a little slack."""
        return max(points, context.record_length) * itemsize + BLOCK_SLACK_BYTES


def split_outside_quotes(text: str, separator: str = ";") -> list[str]:
    """Split a reply at `separator` except inside "..." strings."""
    fields, current, quoted = [], [], False
    for char in text:
        if char == '"':
            quoted = not quoted
        if char == separator and not quoted:
            fields.append("".join(current))
            current = []
        else:
            current.append(char)
    fields.append("".join(current))
    return [f.strip() for f in fields]


def check_preamble(command: str, reply: str, *, points: int, interval_s: float, scale_v: float,
                   offset_v: float) -> None:
    """Refuse preamble values no record can have."""
    if points < 0 or not interval_s > 0 or not scale_v != 0 or offset_v != offset_v:
        raise ReplyFormatError(command, "preamble values out of range", reply)


def check_points(command: str, reply: str, points: int, context: DigitizerSettings) -> None:
    """Refuse a record shorter than the configured one: a decimated or partial transfer (e.g.
    an oscilloscope's default of sending the screen's 1000 points) is not the shot's record."""
    if points < context.record_length:
        raise ReplyFormatError(command, f"the instrument sends {points} points of the {context.record_length} "
                                        "configured (a decimated or partial transfer)", reply)


# -- the generic SCPI dialect ------------------------------------------------------------------

_GENERIC_FORMATS = {"int8": "INT8", "uint8": "UINT8", "int16": "INT16", "uint16": "UINT16", "float32": "FLOAT32"}
_GENERIC_ORDERS = {"little": "LSBF", "big": "MSBF"}


class ScpiErrorQueueDialect(DigitizerDialect):
    """Shared by SCPI instruments with an error queue (:SYSTem:ERRor?): a command is sent with
    *CLS before and the error query after, in one message."""

    error_query: ClassVar[str] = ":SYSTem:ERRor?"

    def command(self, link: ScpiLink, *units: str) -> None:
        """Send setting commands with the error query in one message; raise if refused."""
        command = self.join(*units)
        reply = link.query(self.join("*CLS", command, self.error_query))
        code, message = self.parse_error(command, reply)
        if code != 0:
            raise CommandRefused(command, f"refused by the instrument (error {code}: {message})", reply)

    @staticmethod
    def parse_error(command: str, reply: str) -> tuple[int, str]:
        """'<code>,"<message>"' -> (code, message); code 0 means no error."""
        code_text, _, message = reply.strip().partition(",")
        try:
            code = int(code_text)
        except ValueError:
            raise ReplyFormatError(command, f"not an error-queue reply: {reply!r}", reply) from None
        return code, message.strip().strip('"')


class GenericScpiDialect(ScpiErrorQueueDialect):
    """The generic SCPI digitizer (module docstring)."""

    name = "generic"
    channel_names = ("CH1", "CH2", "CH3", "CH4")
    external_trigger = "EXT"

    def prepare(self, link: ScpiLink) -> None:
        self.command(link, f":WAVeform:FORMat {_GENERIC_FORMATS[self.transfer.sample_format]}",
                     f":WAVeform:BYTeorder {_GENERIC_ORDERS[self.transfer.byte_order]}")

    def apply(self, link: ScpiLink, settings: DigitizerSettings) -> None:
        units = self.turn_on_units(settings)
        units += [f":ACQuire:SRATe {settings.sample_rate_hz!r}", f":ACQuire:POINts {settings.record_length:d}",
                  f":ACQuire:PRETrigger {settings.pre_trigger_samples:d}"]
        units += [f":CHANnel{self.channel_number(ch):d}:RANGe {float(r)!r}" for ch, r in settings.ranges_v.items()]
        units += [f":TRIGger:SOURce {settings.trigger_source}", f":TRIGger:LEVel {float(settings.trigger_level_v)!r}",
                  f":TRIGger:SLOPe {settings.trigger_slope}"]
        self.command(link, *units)

    def read_settings(self, link: ScpiLink, context: DigitizerSettings) -> DigitizerSettings:
        channels = context.channels
        units = [":ACQuire:SRATe?", ":ACQuire:POINts?", ":ACQuire:PRETrigger?"]
        units += [f":CHANnel{self.channel_number(ch):d}:RANGe?" for ch in channels]
        units += [":TRIGger:SOURce?", ":TRIGger:LEVel?", ":TRIGger:SLOPe?"]
        fields = self.query_fields(link, units)
        command = self.join(*units)
        n = len(channels)
        held = DigitizerSettings(
            sample_rate_hz=self.number(command, fields[0]),
            record_length=self.integer(command, fields[1]),
            pre_trigger_samples=self.integer(command, fields[2]),
            ranges_v={ch: self.number(command, f) for ch, f in zip(channels, fields[3:3 + n], strict=True)},
            trigger_source=fields[3 + n].upper(),
            trigger_level_v=self.number(command, fields[4 + n]),
            trigger_slope=fields[5 + n].upper(),
        )
        return self.with_channels_on(link, held, context)

    def on_command(self, channel: str) -> str | None:
        return f":CHANnel{self.channel_number(channel):d}:DISPlay ON"

    def on_query(self, channel: str) -> str | None:
        return f":CHANnel{self.channel_number(channel):d}:DISPlay?"

    def arm(self, link: ScpiLink) -> None:
        self.command(link, ":SINGle")

    def abort(self, link: ScpiLink) -> None:
        self.command(link, ":ABORt")

    def state(self, link: ScpiLink) -> str:
        command = ":ACQuire:STATe?"
        reply = link.query(command)
        state = reply.strip().upper()
        if state not in ACQUISITION_STATES:
            raise ReplyFormatError(command, f"unknown acquisition state {reply!r}", reply)
        return state

    def fetch(self, link: ScpiLink, channel: str, context: DigitizerSettings) -> Waveform:
        n = self.channel_number(channel)
        units = [f":WAVeform:SOURce CH{n:d}", ":WAVeform:PREamble?", f":CHANnel{n:d}:RANGe?"]
        command = self.join(*units)
        preamble, range_text = self.query_fields(link, units, count=2)
        reply = self.join(preamble, range_text)
        fields = [f.strip() for f in preamble.split(",")]
        if len(fields) != 7:
            raise ReplyFormatError(command, f"preamble has {len(fields)} fields, expected 7", reply)
        formats = {v: k for k, v in _GENERIC_FORMATS.items()}
        orders = {v: k for k, v in _GENERIC_ORDERS.items()}
        fmt, order = formats.get(fields[0].upper()), orders.get(fields[1].upper())
        if fmt is None:
            raise ReplyFormatError(command, f"unsupported sample format {fields[0]!r}", reply)
        if order is None:
            raise ReplyFormatError(command, f"unknown byte order {fields[1]!r} (expected LSBF or MSBF)", reply)
        try:
            points, trigger_index = int(fields[2]), int(fields[4])
            interval_s, scale_v, offset_v = float(fields[3]), float(fields[5]), float(fields[6])
            range_v = float(range_text)
        except ValueError:
            raise ReplyFormatError(command, "preamble has a non-numeric field", reply) from None
        return self.fetch_samples(link, ":WAVeform:DATA?", channel, context, preamble=(command, reply),
                                  points=points, dtype=sample_dtype(fmt, order), scale_v=scale_v, offset_v=offset_v,
                                  sample_interval_s=interval_s, trigger_index=trigger_index, range_v=range_v)


DIALECTS: dict[str, str] = {
    "generic": "hopkinson.drivers.scpi_dialect:GenericScpiDialect",
    "keysight": "hopkinson.drivers.digitizer_keysight:KeysightDialect",
    "tektronix": "hopkinson.drivers.digitizer_tektronix:TektronixDialect",
    "lecroy": "hopkinson.drivers.digitizer_lecroy:LeCroyDialect",
}


def resolve_dialect(name: str) -> type[DigitizerDialect]:
    """The dialect class for a configured name: one of DIALECTS, or "package.module:Class".

    Raises ValueError (one line: what was wrong) for an unknown name, a module that does not
    import, or a class that is not a DigitizerDialect.
    """
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"dialect must be a name ({', '.join(DIALECTS)}) or 'package.module:Class', got {name!r}")
    target = DIALECTS.get(name.strip().lower(), name.strip())
    module_name, _, class_name = target.partition(":")
    if not class_name:
        raise ValueError(f"unknown dialect {name!r}: use one of {', '.join(DIALECTS)} or 'package.module:Class'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"dialect {name!r}: cannot import {module_name}: {exc}") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, DigitizerDialect)):
        raise ValueError(f"dialect {name!r}: {class_name} in {module_name} is not a DigitizerDialect subclass")
    return cls
