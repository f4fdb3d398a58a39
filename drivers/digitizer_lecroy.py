"""LeCroy-style oscilloscopes (WaveRunner/WavePro remote control) as the rig's digitizer.

Commands (LeCroy remote control manual; short forms, CHDR OFF: no headers, no units):
    CHDR OFF                                    COMM_HEADER: replies without header or unit
    CFMT DEF9,WORD,BIN | DEF9,BYTE,BIN          COMM_FORMAT: IEEE 488.2 block, 16- or 8-bit signed
    CORD LO | HI                                COMM_ORDER: byte order of the block
    WFSU SP,0,NP,0,FP,0,SN,0                    WAVEFORM_SETUP: every point from the first
    MSIZ <n>, TDIV <s/div>                      memory size and time base (10 divisions): the
                                                sample rate is MSIZ / (10·TDIV); SARA? reads it
    TRDL <percent>                              TRIG_DELAY: pre-trigger as % of the record
    C<n>:VDIV <V/div>, C<n>:OFST 0              8 divisions: a ±10 V channel is 2.5 V/div
    C<n>:TRA ON | ? (ON|OFF)                    TRACE: a channel that is off is not acquired (the
                                                default setup shows C1 only; an off channel's
                                                waveform is an empty trace)
    TRSE EDGE,SR,C<n>|EX                        TRIG_SELECT: edge trigger and its source
    C<n>:TRLV <v>, C<n>:TRSL POS|NEG            TRIG_LEVEL and TRIG_SLOPE of that source
    TRMD SINGLE | STOP, TRMD?                   TRIG_MODE: arm one acquisition / stop
    INR?                                        internal state register (read clears): bit 0 = a
                                                new signal was acquired
    C<n>:WF? ALL                                the waveform: a block holding the WAVEDESC
                                                descriptor (346 bytes, template LECROY_2_3),
                                                then the samples
    errors: CMR? (command error register) and EXR? (execution error register), 0 = none

WAVEDESC fields used (byte offsets, in the byte order of COMM_ORDER at offset 34):
    0 DESCRIPTOR_NAME "WAVEDESC", 32 COMM_TYPE (0 byte, 1 word), 34 COMM_ORDER (0 HI, 1 LO),
    36 WAVE_DESCRIPTOR, 40 USER_TEXT, 48 TRIGTIME_ARRAY, 52 RIS_TIME_ARRAY (block lengths),
    60 WAVE_ARRAY_1 (bytes of samples), 116 WAVE_ARRAY_COUNT (points), 156 VERTICAL_GAIN (f32),
    160 VERTICAL_OFFSET (f32), 176 HORIZ_INTERVAL (f32), 180 HORIZ_OFFSET (f64, time of the
    first point from the trigger). volts = VERTICAL_GAIN·code − VERTICAL_OFFSET.

State: TRMD? reads SINGLE while armed and STOP after the acquisition (or a stop); INR? bit 0
tells which. Reading INR? clears it, so the dialect latches a new acquisition it has seen
until the next arm or stop.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from hopkinson.drivers.digitizer_settings import DigitizerSettings, pre_trigger_samples
from hopkinson.drivers.digitizer_waveform import Waveform, sample_dtype
from hopkinson.drivers.scpi_dialect import (
    CommandRefused,
    DigitizerDialect,
    ReplyFormatError,
    ScpiLink,
    check_points,
    check_preamble,
    split_outside_quotes,
)

VERTICAL_DIVISIONS = 8
HORIZONTAL_DIVISIONS = 10
WAVEDESC_BYTES = 346
_HEADER_MAX = 64  # response header text a block may carry before the '#' ("C1:WF ALL,")
_COMMAND_ERRORS = {1: "unrecognized command/query header", 2: "illegal header path", 3: "illegal number",
                   4: "illegal number suffix", 5: "unrecognized keyword", 6: "string error",
                   7: "GET embedded in another message", 10: "arbitrary data block expected",
                   11: "non-digit character in byte count field of arbitrary data block",
                   12: "EOI detected during definite length data block transfer",
                   13: "extra bytes detected during definite length data block transfer"}
_EXECUTION_ERRORS = {21: "permission error", 22: "environment error", 23: "option error",
                     24: "unresolved parsing error", 25: "parameter error", 26: "command not implemented",
                     27: "parameter missing", 31: "waveform error", 32: "waveform descriptor error"}
_NEW_SIGNAL = 0x0001  # INR? bit 0


class LeCroyDialect(DigitizerDialect):
    """LeCroy-style commands, replies and the WAVEDESC descriptor (module docstring)."""

    name = "lecroy"
    channel_names = ("C1", "C2", "C3", "C4")
    external_trigger = "EX"
    sample_formats = ("int8", "int16")

    channel_prefix = "C"

    def command(self, link: ScpiLink, *units: str) -> None:
        """Send commands, then CMR? and EXR? in the same message; raise if either is set."""
        command = self.join(*units)
        reply = link.query(self.join("*CLS", command, "CMR?", "EXR?"))
        fields = split_outside_quotes(reply, ";")
        if len(fields) != 2:
            raise ReplyFormatError(command, "expected the CMR? and EXR? registers", reply)
        cmr, exr = (self.integer(command, f, reply) for f in fields)
        if cmr or exr:
            problems = [f"command error {cmr}: {_COMMAND_ERRORS.get(cmr, 'unknown')}"] if cmr else []
            problems += [f"execution error {exr}: {_EXECUTION_ERRORS.get(exr, 'unknown')}"] if exr else []
            raise CommandRefused(command, f"refused by the instrument ({'; '.join(problems)})", reply)

    def prepare(self, link: ScpiLink) -> None:
        width = "WORD" if self.transfer.sample_format == "int16" else "BYTE"
        order = "LO" if self.transfer.byte_order == "little" else "HI"
        self.command(link, "CHDR OFF", f"CFMT DEF9,{width},BIN", f"CORD {order}", "WFSU SP,0,NP,0,FP,0,SN,0")

    def apply(self, link: ScpiLink, settings: DigitizerSettings) -> None:
        time_per_div = settings.record_length / (HORIZONTAL_DIVISIONS * settings.sample_rate_hz)
        percent = 100.0 * settings.pre_trigger_samples / settings.record_length
        units = self.turn_on_units(settings)
        units += [f"MSIZ {settings.record_length:d}", f"TDIV {time_per_div:.6E}", f"TRDL {percent:.6f}"]
        for ch, range_v in settings.ranges_v.items():
            units += [f"{ch}:VDIV {2 * float(range_v) / VERTICAL_DIVISIONS:.6E}", f"{ch}:OFST 0"]
        source = settings.trigger_source
        units += [f"TRSE EDGE,SR,{source}", f"{source}:TRLV {float(settings.trigger_level_v):.6E}",
                  f"{source}:TRSL {settings.trigger_slope}"]
        self.command(link, *units)

    def read_settings(self, link: ScpiLink, context: DigitizerSettings) -> DigitizerSettings:
        channels = context.channels
        units = ["SARA?", "MSIZ?", "TRDL?", *(f"{ch}:VDIV?" for ch in channels), "TRSE?"]
        command = self.join(*units)
        fields = split_outside_quotes(link.query(command), ";")
        n = len(channels)
        if len(fields) != 4 + n:
            raise ReplyFormatError(command, f"expected {4 + n} replies, got {len(fields)}", ";".join(fields))
        rate, points = self.number(command, fields[0]), self.integer(command, fields[1])
        percent = self.number(command, fields[2])
        select = [f.strip().upper() for f in fields[3 + n].split(",")]
        if len(select) < 3 or select[0] != "EDGE" or select[1] != "SR":
            raise ReplyFormatError(command, f"not an edge trigger: TRSE? {fields[3 + n]!r}", ";".join(fields))
        source = self.trigger_source_name(select[2])
        level_units = [f"{source}:TRLV?", f"{source}:TRSL?"]
        level_text, slope = self.query_fields(link, level_units)
        held = DigitizerSettings(
            sample_rate_hz=rate, record_length=points,
            pre_trigger_samples=pre_trigger_samples(percent / 100.0, points),
            ranges_v={ch: self.number(command, f) * VERTICAL_DIVISIONS / 2
                      for ch, f in zip(channels, fields[3:3 + n], strict=True)},
            trigger_source=source, trigger_level_v=self.number(self.join(*level_units), level_text),
            trigger_slope=slope.upper(),
        )
        return self.with_channels_on(link, held, context)

    def on_command(self, channel: str) -> str | None:
        return f"{channel}:TRA ON"

    def on_query(self, channel: str) -> str | None:
        return f"{channel}:TRA?"

    def arm(self, link: ScpiLink) -> None:
        self.forget_completion()
        self.command(link, "TRMD SINGLE")

    def abort(self, link: ScpiLink) -> None:
        self.forget_completion()
        self.command(link, "TRMD STOP")

    def state(self, link: ScpiLink) -> str:
        return self.latched_state(link, "TRMD?", "INR?", armed=("SINGLE", "NORM", "NORMAL", "AUTO"), stopped="STOP",
                                  completed=_NEW_SIGNAL)

    def fetch(self, link: ScpiLink, channel: str, context: DigitizerSettings) -> Waveform:
        command = f"{channel}:WF? ALL"
        itemsize = 2 if self.transfer.sample_format == "int16" else 1
        limit = self.block_limit(context, context.record_length, itemsize)
        _, block = link.query_block(command, limit, header_max=_HEADER_MAX)
        desc = parse_wavedesc(command, block)
        if desc.points == 0:  # an empty trace: a channel that is off has one
            self.refuse_if_off(link, channel, command, "")
            raise ReplyFormatError(command, f"no acquired record on {channel}")
        check_points(command, "", desc.points, context)
        start = desc.data_offset
        payload = block[start:start + desc.data_bytes]
        if len(payload) != desc.data_bytes or start + desc.data_bytes != len(block):
            raise ReplyFormatError(command, f"the block holds {len(block)} bytes; the descriptor announces "
                                            f"{start} + {desc.data_bytes}")
        return self.waveform(command, channel, payload, points=desc.points,
                             dtype=sample_dtype(desc.sample_format, desc.byte_order), scale_v=desc.gain_v,
                             offset_v=-desc.offset_v, sample_interval_s=desc.interval_s,
                             trigger_index=int(round(-desc.first_time_s / desc.interval_s)))


@dataclass(frozen=True)
class WaveDesc:
    """The fields of a WAVEDESC descriptor the driver needs (module docstring)."""

    sample_format: str
    byte_order: str
    data_offset: int
    data_bytes: int
    points: int
    gain_v: float
    offset_v: float
    interval_s: float
    first_time_s: float


def parse_wavedesc(command: str, block: memoryview | bytes) -> WaveDesc:
    """Parse the WAVEDESC at the start of a waveform block; ReplyFormatError if it is not one."""
    head = bytes(block[:WAVEDESC_BYTES])
    if len(head) < WAVEDESC_BYTES or not head.startswith(b"WAVEDESC"):
        raise ReplyFormatError(command, "the block does not start with a WAVEDESC descriptor", head[:40])
    order_flag = struct.unpack_from("<H", head, 34)[0]
    if order_flag not in (0, 1):
        raise ReplyFormatError(command, f"WAVEDESC COMM_ORDER {order_flag} is neither 0 (HI) nor 1 (LO)", head[:40])
    e = "<" if order_flag == 1 else ">"
    comm_type = struct.unpack_from(e + "h", head, 32)[0]
    if comm_type not in (0, 1):
        raise ReplyFormatError(command, f"WAVEDESC COMM_TYPE {comm_type} is neither 0 (byte) nor 1 (word)", head[:40])
    desc_len, user_text = struct.unpack_from(e + "ii", head, 36)
    trigtime, ris_time = struct.unpack_from(e + "ii", head, 48)
    data_bytes = struct.unpack_from(e + "i", head, 60)[0]
    points = struct.unpack_from(e + "i", head, 116)[0]
    gain, offset = struct.unpack_from(e + "ff", head, 156)
    interval = struct.unpack_from(e + "f", head, 176)[0]
    first_time = struct.unpack_from(e + "d", head, 180)[0]
    sample_format = "int16" if comm_type == 1 else "int8"
    lengths = (desc_len, user_text, trigtime, ris_time, data_bytes, points)
    if desc_len < WAVEDESC_BYTES or min(lengths) < 0:
        raise ReplyFormatError(command, f"WAVEDESC block lengths out of range: {lengths}", head[:40])
    if data_bytes != points * (2 if comm_type == 1 else 1):
        raise ReplyFormatError(command, f"WAVEDESC: WAVE_ARRAY_1 = {data_bytes} bytes for {points} points "
                                        f"of {sample_format}", head[:40])
    check_preamble(command, "", points=points, interval_s=interval, scale_v=gain, offset_v=offset)
    return WaveDesc(sample_format, "little" if e == "<" else "big", desc_len + user_text + trigtime + ris_time,
                    data_bytes, points, float(gain), float(offset), float(interval), float(first_time))
