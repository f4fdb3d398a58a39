"""Simulated LeCroy-style oscilloscope (WaveRunner/WavePro remote control; its side).

Written from the LeCroy remote control manual and the LECROY_2_3 waveform template,
independently of drivers/digitizer_lecroy.py. Every command has its long and short name
(COMM_HEADER and CHDR). Replies carry a short header until CHDR OFF ("C1:VDIV 2.50E+00 V";
with OFF: "2.50E+00"). Numbers may carry LeCroy's multipliers and units ("10K", "2.5 V",
"10 PCT"). Over the raw socket the messages end with "\\n" (a real instrument's VICP or VXI-11
framing is the VISA layer's business).

    CHDR OFF|SHORT|LONG, CFMT DEF9,BYTE|WORD,BIN, CORD HI|LO, WFSU SP,<n>,NP,<n>,FP,<n>,SN,<n>
    MSIZ <points>, TDIV <s/div> (10 divisions: sample rate = MSIZ / (10·TDIV)), SARA? (the rate)
    TRDL <percent>            pre-trigger as % of the record (0 .. 100)
    C<n>:VDIV <V/div>         8 divisions: the channel reads ±4·VDIV;   C<n>:OFST <v> (0 only)
    C<n>:TRACE|TRA ON|OFF | ? the default setup (*RST) shows C1 only; a channel that is off is
                              not acquired: its waveform is an empty trace (a WAVEDESC, no data)
    TRSE EDGE,SR,C<n>|EX[,HT,OFF] | ?, C<n>|EX:TRLV <v> | ?, C<n>|EX:TRSL POS|NEG | ?
    TRMD AUTO|NORM|SINGLE|STOP | ?, ARM, STOP
    INR?   bit 0: a new signal was acquired, bit 13: the trigger became ready (read clears)
    CMR?   command error register (1 unrecognized header, 2 illegal header path, 3 illegal
           number, ...), EXR? execution error register (21 permission, 22 environment,
           25 parameter error, 27 parameter missing, 31 waveform error); both clear on read
    C<n>:WF? [ALL|DESC|DAT1]  the waveform block: WAVEDESC (346 bytes) and/or the samples
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable

import numpy as np

from hopkinson.drivers.sim.scpi_instrument import SimDigitizer
from hopkinson.drivers.sim.scpi_messages import Block, Call, Handler, Reply, SimError

WAVEDESC_BYTES = 346
_MULTIPLIERS = {"": 1.0, "K": 1e3, "MA": 1e6, "M": 1e-3, "U": 1e-6, "N": 1e-9, "P": 1e-12, "G": 1e9}
# SCPI-numbered errors -> (register, code) in LeCroy's CMR/EXR registers
_REGISTER = {-113: ("cmr", 1), -114: ("cmr", 2), -104: ("cmr", 3), -109: ("exr", 27), -221: ("exr", 22),
             -222: ("exr", 25), -224: ("exr", 25), -230: ("exr", 31), -240: ("exr", 22)}


def lecroy_number(arg: str) -> float:
    """A LeCroy numeric parameter: mantissa, optional multiplier (K, MA, M, U, N, P) and unit."""
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(MA|[KMUNPG])?\s*(V|S|PCT|HZ|%)?\s*",
                     arg.upper())
    if m is None:
        raise SimError(-104 if arg.strip() else -109, "Data type error")
    value = float(m.group(1)) * _MULTIPLIERS[m.group(2) or ""]
    if not np.isfinite(value):
        raise SimError(-224, "Illegal parameter value")
    return value


class LeCroySimDigitizer(SimDigitizer):
    """The simulated LeCroy-style instrument (module docstring)."""

    identity = "LECROY,HOPKINSON-SIM-LC,SIM0004,9.6.0"
    power_on_channels = (1,)

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.cmr, self.exr, self.inr = 0, 0, 0
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def reset(self) -> None:
        with self.lock:
            super().reset()
            s = self.settings
            self.header = "SHORT"
            self.word, self.order = "WORD", "HI"
            self.trigger_percent = 50.0
            self.levels = {name: 0.0 for name in ("C1", "C2", "C3", "C4", "EX")}
            self.slopes = {name: "POS" for name in self.levels}
            s.trigger_source, s.trigger_level_v, s.trigger_slope = "CH1", 0.0, "POS"
            self.trigger_source_name = "C1"
            self.time_per_div_s = s.record_length / (10 * s.sample_rate_hz)
            self._transfer_format()
            self._place_trigger()

    def table(self) -> list[tuple[tuple[str, ...], Handler]]:
        h = self._headed
        return [
            (("COMM_HEADER|CHDR",), h(self._comm_header)),
            (("COMM_FORMAT|CFMT",), h(self._comm_format)),
            (("COMM_ORDER|CORD",), h(self._comm_order)),
            (("WAVEFORM_SETUP|WFSU",), h(self._waveform_setup)),
            (("MEMORY_SIZE|MSIZ",), h(self._memory_size)),
            (("TIME_DIV|TDIV",), h(self._time_div)),
            (("SAMPLE_RATE|SARA",), h(self._sample_rate)),
            (("TRIG_DELAY|TRDL",), h(self._trigger_delay)),
            (("C<n>", "VOLT_DIV|VDIV"), h(self._volt_div)),
            (("C<n>", "OFFSET|OFST"), h(lambda c: self.zero_only(c, "0.000E+00"))),
            (("C<n>", "TRACE|TRA"), h(lambda c: self.channel_state(c, "ON", "OFF"))),
            (("TRIG_SELECT|TRSE",), h(self._trigger_select)),
            (("C<n>|EX", "TRIG_LEVEL|TRLV"), h(self._trigger_level)),
            (("C<n>|EX", "TRIG_SLOPE|TRSL"), h(self._trigger_slope)),
            (("TRIG_MODE|TRMD",), h(self._trigger_mode)),
            (("ARM_ACQUISITION|ARM",), self._arm),
            (("STOP",), self._stop),
            (("INR",), h(self._inr)),
            (("CMR",), h(self._cmr)),
            (("EXR",), h(self._exr)),
            (("C<n>", "WAVEFORM|WF"), self._waveform),
        ]

    def _headed(self, handler: Handler) -> Callable[[Call], Reply]:
        """A query's reply with its header (short or long name) unless CHDR OFF."""
        def run(c: Call) -> Reply:
            reply = handler(c)
            if isinstance(reply, str) and self.header != "OFF":
                return f"{self._header_of(c)} {reply}"
            return reply
        return run

    def _header_of(self, c: Call) -> str:
        parts = []
        for pattern, suffix in zip(c.nodes, c.node_suffixes, strict=True):
            long, _, short = pattern.partition("|")
            name = long if self.header == "LONG" else (short or long)
            parts.append(name.replace("<n>", "") + ("" if suffix is None else str(suffix)))
        return ":".join(parts)

    # -- status registers ----------------------------------------------------------------------
    def record_error(self, code: int, message: str) -> None:
        self.esr |= self.esr_bit(code)
        register, value = _REGISTER.get(code, ("cmr", 1) if abs(code) < 200 else ("exr", 25))
        setattr(self, register, value)

    def clear_status(self) -> None:
        self.cmr = self.exr = self.inr = 0

    def _register(self, c: Call, name: str) -> Reply:
        c.query_only()
        value = getattr(self, name)
        setattr(self, name, 0)
        return str(value)

    def _cmr(self, c: Call) -> Reply:
        return self._register(c, "cmr")

    def _exr(self, c: Call) -> Reply:
        return self._register(c, "exr")

    def _inr(self, c: Call) -> Reply:
        self.poll_capture()
        return self._register(c, "inr")

    def poll_capture(self) -> None:
        before = self.acquisitions
        super().poll_capture()
        if self.acquisitions > before:
            self.inr |= 0x0001

    # -- communication format -------------------------------------------------------------------
    def _comm_header(self, c: Call) -> Reply:
        if c.query:
            return self.header
        self.header = self.choice(c.arg, ("OFF", "SHORT", "LONG"))
        return None

    def _transfer_format(self) -> None:
        self.sample_format = "int16" if self.word == "WORD" else "int8"
        self.byte_order = "little" if self.order == "LO" else "big"

    def _comm_format(self, c: Call) -> Reply:
        if c.query:
            return f"DEF9,{self.word},BIN"
        args = [a.upper() for a in c.args]
        if len(args) != 3 or args[0] != "DEF9" or args[1] not in ("BYTE", "WORD") or args[2] != "BIN":
            raise SimError(-224, "Illegal parameter value")
        self.word = args[1]
        self._transfer_format()
        return None

    def _comm_order(self, c: Call) -> Reply:
        if c.query:
            return self.order
        self.order = self.choice(c.arg, ("HI", "LO"))
        self._transfer_format()
        return None

    def _waveform_setup(self, c: Call) -> Reply:
        if c.query:
            return "SP,0,NP,0,FP,0,SN,0"
        args = [a.upper() for a in c.args]
        if len(args) % 2 or any(k not in ("SP", "NP", "FP", "SN") for k in args[::2]):
            raise SimError(-224, "Illegal parameter value")
        allowed = {"SP": (0.0, 1.0), "NP": (0.0,), "FP": (0.0,)}
        for key, value in zip(args[::2], args[1::2], strict=True):
            if lecroy_number(value) not in allowed.get(key, (lecroy_number(value),)):
                raise SimError(-221, "Settings conflict; only every point from the first is simulated")
        return None

    # -- timebase -------------------------------------------------------------------------------
    def _place_trigger(self) -> None:
        s = self.settings
        s.pre_trigger_samples = min(max(round(self.trigger_percent / 100.0 * s.record_length), 0), s.record_length - 1)

    def _rate_from_timebase(self) -> None:
        self.set_sample_rate(self.settings.record_length / (10.0 * self.time_per_div_s))

    def _memory_size(self, c: Call) -> Reply:
        if c.query:
            return f"{self.settings.record_length:.4E}"
        points = lecroy_number(c.arg)
        if points != int(points):
            raise SimError(-224, "Illegal parameter value")
        old = self.settings.record_length
        self.set_record_length(int(points))
        try:
            self._rate_from_timebase()
        except SimError:
            self.settings.record_length = old
            raise
        self._place_trigger()
        return None

    def _time_div(self, c: Call) -> Reply:
        if c.query:
            return f"{self.time_per_div_s:.6E}"
        value = lecroy_number(c.arg)
        if not value > 0:
            raise SimError(-222, "Data out of range")
        old, self.time_per_div_s = self.time_per_div_s, value
        try:
            self._rate_from_timebase()
        except SimError:
            self.time_per_div_s = old
            raise
        return None

    def _sample_rate(self, c: Call) -> Reply:
        c.query_only()
        return f"{self.settings.sample_rate_hz:.6E}"

    def _trigger_delay(self, c: Call) -> Reply:
        if c.query:
            return f"{self.trigger_percent:.4f}"
        value = lecroy_number(c.arg)
        if value < 0:
            raise SimError(-221, "Settings conflict; post-trigger delays are not simulated")
        self.in_range(value, (0.0, 100.0))
        self.not_while_armed()
        self.trigger_percent = value
        self._place_trigger()
        return None

    def _volt_div(self, c: Call) -> Reply:
        channel = self.channel(c.suffix)
        if c.query:
            return f"{self.settings.ch_range_v[channel] / 4:.6E}"
        self.set_range(channel, lecroy_number(c.arg) * 4)
        return None

    # -- trigger --------------------------------------------------------------------------------
    @staticmethod
    def _source_name(c: Call) -> str:
        return f"C{c.suffixes[0]}" if c.suffixes else "EX"

    def _sync_trigger(self, source: str) -> None:
        """The effective trigger: the selected source with its own level and slope."""
        self.set_trigger(source="EXT" if source == "EX" else f"CH{source[1:]}", level_v=self.levels[source],
                         slope=self.slopes[source])
        self.trigger_source_name = source

    def _trigger_select(self, c: Call) -> Reply:
        current = self.trigger_source_name
        if c.query:
            return f"EDGE,SR,{current},HT,OFF"
        args = [a.upper() for a in c.args]
        if len(args) < 3 or args[0] != "EDGE" or args[1] != "SR":
            raise SimError(-224, "Illegal parameter value")
        source = args[2]
        if source not in self.levels:
            raise SimError(-224, "Illegal parameter value")
        self._sync_trigger(source)
        return None

    def _trigger_level(self, c: Call) -> Reply:
        source = self._source_name(c)
        if c.query:
            return f"{self.levels[source]:.6E}"
        value = lecroy_number(c.arg)
        self.in_range(abs(value), (0.0, 100.0))
        self.not_while_armed()
        self.levels[source] = value
        if source == self.trigger_source_name:
            self._sync_trigger(source)
        return None

    def _trigger_slope(self, c: Call) -> Reply:
        source = self._source_name(c)
        if c.query:
            return self.slopes[source]
        self.not_while_armed()
        self.slopes[source] = self.choice(c.arg, ("POS", "NEG"))
        if source == self.trigger_source_name:
            self._sync_trigger(source)
        return None

    def _trigger_mode(self, c: Call) -> Reply:
        if c.query:
            self.poll_capture()
            return "SINGLE" if self.state == "ARMED" else "STOP"
        mode = self.choice(c.arg, ("AUTO", "NORM", "SINGLE", "STOP"))
        if mode == "STOP":
            return self.stop()
        if mode in ("AUTO", "NORM"):
            raise SimError(-221, "Settings conflict; only SINGLE and STOP are simulated")
        return self._arm_now()

    def _arm_now(self) -> Reply:
        self.arm()
        self.inr |= 0x2000  # the trigger is ready
        return None

    def _arm(self, c: Call) -> Reply:
        c.command_only()
        return self._arm_now()

    def _stop(self, c: Call) -> Reply:
        c.command_only()
        return self.stop()

    # -- the waveform ---------------------------------------------------------------------------
    def _waveform(self, c: Call) -> Reply:
        c.query_only()
        part = (c.arg or "ALL").upper()
        if part not in ("ALL", "DESC", "DAT1"):
            raise SimError(-224, "Illegal parameter value")
        channel = self.channel(c.suffix)
        self.poll_capture()
        encoded = self.encoded(channel)
        payload, scale = (encoded[0], encoded[1]) if encoded else (b"", self.settings.ch_range_v[channel] / 32767)
        desc = self._wavedesc(channel, len(payload), scale)  # no acquisition: an empty trace
        prefix = "" if self.header == "OFF" else f"{self._header_of(c)} {part},"
        if part == "DESC":
            return Block(desc, prefix=prefix, digits=9)
        return Block(payload, prefix=prefix, digits=9, lead=desc if part == "ALL" else b"")

    def _wavedesc(self, channel: int, data_bytes: int, gain_v: float) -> bytes:
        """The 346-byte WAVEDESC (template LECROY_2_3) in the COMM_ORDER byte order."""
        s = self.settings
        e = "<" if self.order == "LO" else ">"
        d = bytearray(WAVEDESC_BYTES)
        d[0:8], d[16:26] = b"WAVEDESC", b"LECROY_2_3"
        struct.pack_into(e + "hh", d, 32, 1 if self.word == "WORD" else 0, 1 if self.order == "LO" else 0)
        struct.pack_into(e + "iiiiiiiiii", d, 36, WAVEDESC_BYTES, 0, 0, 0, 0, 0, data_bytes, 0, 0, 0)
        d[76:89] = b"HOPKINSON-SIM"
        struct.pack_into(e + "i", d, 92, 4)
        n = data_bytes // (2 if self.word == "WORD" else 1)
        struct.pack_into(e + "iiiiiiiii", d, 116, n, n, 0, max(n - 1, 0), 0, 1, 0, 1, 1)
        full = 127 if self.word == "BYTE" else 32767
        struct.pack_into(e + "ffffhh", d, 156, gain_v, 0.0, float(full), float(-full), 8, 1)
        struct.pack_into(e + "fdd", d, 176, 1.0 / s.sample_rate_hz, -s.pre_trigger_samples / s.sample_rate_hz, 0.0)
        d[196:197], d[244:245] = b"V", b"S"
        struct.pack_into(e + "hhhhhhfhhff", d, 316, 0, 0, 0, 1, 0, 2, 1.0, 0, 0, 1.0, 0.0)
        struct.pack_into(e + "h", d, 344, channel - 1)
        return bytes(d)
