"""The digitizer's SCPI dialect in one place: command text out, replies parsed in.

The driver (drivers/digitizer.py) never spells a SCPI header itself; it asks a dialect. A
second vendor is one subclass overriding the commands that differ (e.g. ":TIMebase:SRATe"
instead of ":ACQuire:SRATe", a different state word or preamble layout).

`GenericScpiDialect` is the dialect of the simulated digitizer (drivers/sim/scpi_digitizer.py):
    :ACQuire:SRATe/POINts/PRETrigger, :CHANnel<n>:RANGe (full scale, +-v), :TRIGger:SOURce/LEVel/
    SLOPe, :SINGle, :ABORt, :ACQuire:STATe? (IDLE|ARMED|TRIGGERED), :WAVeform:SOURce/PREamble?/
    DATA? (IEEE 488.2 block of little-endian int16), errors from :SYSTem:ERRor?.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ACQUISITION_STATES = ("IDLE", "ARMED", "TRIGGERED")


class ReplyFormatError(ValueError):
    """A reply that the dialect cannot parse (the driver adds instrument and command)."""


@dataclass(frozen=True)
class Preamble:
    """How to read one channel's waveform block: volts = code * scale_v + offset_v."""

    points: int
    sample_interval_s: float
    trigger_index: int
    scale_v: float
    offset_v: float
    dtype: np.dtype


class GenericScpiDialect:
    """Commands and reply parsers of a generic two-channel SCPI digitizer."""

    name = "generic"
    channels: tuple[int, ...] = (1, 2)
    trigger_sources: tuple[str, ...] = ("CH1", "CH2", "EXT")
    trigger_slopes: tuple[str, ...] = ("POS", "NEG")

    # -- common ------------------------------------------------------------------------
    identity_query = "*IDN?"
    clear_status = "*CLS"
    error_query = ":SYSTem:ERRor?"
    unit_separator = ";"

    def join(self, *units: str) -> str:
        """Several message units as one message (one round trip)."""
        return self.unit_separator.join(units)

    def parse_error(self, reply: str) -> tuple[int, str]:
        """'<code>,"<message>"' -> (code, message); code 0 means no error."""
        code_text, _, message = reply.strip().partition(",")
        try:
            code = int(code_text)
        except ValueError:
            raise ReplyFormatError(f"not an error-queue reply: {reply!r}") from None
        return code, message.strip().strip('"')

    # -- acquisition settings ----------------------------------------------------------
    def set_sample_rate(self, sample_rate_hz: float) -> str:
        return f":ACQuire:SRATe {sample_rate_hz!r}"

    sample_rate_query = ":ACQuire:SRATe?"

    def set_record_length(self, samples: int) -> str:
        return f":ACQuire:POINts {samples:d}"

    record_length_query = ":ACQuire:POINts?"

    def set_pre_trigger(self, samples: int) -> str:
        return f":ACQuire:PRETrigger {samples:d}"

    pre_trigger_query = ":ACQuire:PRETrigger?"

    def set_channel_range(self, channel: int, full_scale_v: float) -> str:
        return f":CHANnel{channel:d}:RANGe {full_scale_v!r}"

    def channel_range_query(self, channel: int) -> str:
        return f":CHANnel{channel:d}:RANGe?"

    def set_trigger_source(self, source: str) -> str:
        return f":TRIGger:SOURce {source}"

    trigger_source_query = ":TRIGger:SOURce?"

    def set_trigger_level(self, level_v: float) -> str:
        return f":TRIGger:LEVel {level_v!r}"

    trigger_level_query = ":TRIGger:LEVel?"

    def set_trigger_slope(self, slope: str) -> str:
        return f":TRIGger:SLOPe {slope}"

    trigger_slope_query = ":TRIGger:SLOPe?"

    # -- acquisition control -----------------------------------------------------------
    arm_single = ":SINGle"
    abort = ":ABORt"
    state_query = ":ACQuire:STATe?"

    def parse_state(self, reply: str) -> str:
        """The vendor's state word -> one of ACQUISITION_STATES."""
        state = reply.strip().upper()
        if state not in ACQUISITION_STATES:
            raise ReplyFormatError(f"unknown acquisition state {reply!r}")
        return state

    # -- waveform transfer -------------------------------------------------------------
    def select_waveform(self, channel: int) -> str:
        return f":WAVeform:SOURce CH{channel:d}"

    preamble_query = ":WAVeform:PREamble?"
    data_query = ":WAVeform:DATA?"

    def parse_preamble(self, reply: str) -> Preamble:
        """'INT16,LSBF,<points>,<x_increment_s>,<trigger_index>,<y_scale_v>,<y_offset_v>'."""
        fields = [f.strip() for f in reply.strip().split(",")]
        if len(fields) != 7:
            raise ReplyFormatError(f"preamble has {len(fields)} fields, expected 7: {reply!r}")
        fmt, order = fields[0].upper(), fields[1].upper()
        if fmt != "INT16":
            raise ReplyFormatError(f"unsupported sample format {fields[0]!r} (expected INT16)")
        if order not in ("LSBF", "MSBF"):
            raise ReplyFormatError(f"unknown byte order {fields[1]!r} (expected LSBF or MSBF)")
        try:
            points, trigger_index = int(fields[2]), int(fields[4])
            interval_s, scale_v, offset_v = float(fields[3]), float(fields[5]), float(fields[6])
        except ValueError:
            raise ReplyFormatError(f"preamble has a non-numeric field: {reply!r}") from None
        if points < 0 or not interval_s > 0 or not scale_v > 0 or not np.isfinite(offset_v):
            raise ReplyFormatError(f"preamble values out of range: {reply!r}")
        return Preamble(
            points=points,
            sample_interval_s=interval_s,
            trigger_index=trigger_index,
            scale_v=scale_v,
            offset_v=offset_v,
            dtype=np.dtype("<i2" if order == "LSBF" else ">i2"),
        )
