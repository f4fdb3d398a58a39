"""Simulated Keysight InfiniiVision/Infiniium-style oscilloscope (its side of the protocol).

Written from the Keysight programmer's guides, independently of drivers/digitizer_keysight.py.
Numbers are answered in Keysight's NR1/NR3 forms ("+100000", "+1.00000E+08"); keywords in
their short form ("CHAN1", "POS", "LSBF").

    :SYSTem:ERRor? (+0,"No error"), :SYSTem:ERRor:COUNt?
    :ACQuire:SRATe <rate> | ?, :ACQuire:POINts <n> | ?
    :TIMebase:REFerence LEFT|CENTer|RIGHt | ?   the record's reference point (first, middle or
                                                last sample)
    :TIMebase:POSition <s> | ?                  time from the trigger to the reference point
                                                (LEFT and −10 µs: the trigger 10 µs into the record)
    :CHANnel<n>:RANGe <v> | ?                   the full vertical span, 8 divisions (±v/2)
    :CHANnel<n>:OFFSet <v> | ?                  (only 0 is simulated)
    :CHANnel<n>:DISPlay ON|OFF|1|0 | ? (1|0)    after power-on and *RST only channel 1 is on; a
                                                channel that is off is not acquired: its preamble
                                                still announces the record, its :WAVeform:DATA? is
                                                an empty block and -221 "Settings conflict" is queued
    :TRIGger:MODE EDGE | ?, :TRIGger:EDGE:SOURce CHANnel<n>|EXTernal | ?, :TRIGger:EDGE:LEVel
    <v> | ?, :TRIGger:EDGE:SLOPe POSitive|NEGative | ?
    :SINGle, :STOP, :RSTate? (SING while armed, STOP otherwise), :TER? (1 once per trigger)
    :WAVeform:SOURce CHANnel<n> | ?, :WAVeform:FORMat BYTE|WORD | ?, :WAVeform:UNSigned 0|1 | ?,
    :WAVeform:BYTeorder LSBFirst|MSBFirst | ?, :WAVeform:POINts:MODE NORMal|MAXimum|RAW | ?,
    :WAVeform:POINts <n>|MAXimum | ?            points sent; *RST: 1000 (fewer than the record:
                                                every k-th sample, the x increment k times longer)
    :WAVeform:PREamble? (format 0 BYTE / 1 WORD, type, points, count, xincrement, xorigin,
    xreference, yincrement, yorigin, yreference), :WAVeform:DATA? (block; 0x00/0x0000 is a hole,
    the converter clips at 0x01 and 0xFF/0xFFFF, shifted by half the range when signed)
"""

from __future__ import annotations

import numpy as np

from hopkinson.drivers.sim.scpi_instrument import RECORD_LENGTH_LIMITS, SimDigitizer
from hopkinson.drivers.sim.scpi_messages import Block, Call, Handler, Reply, SimError

_REFERENCES = {"LEFT": 0.0, "CENTer": 0.5, "RIGHt": 1.0}


class KeysightSimDigitizer(SimDigitizer):
    """The simulated Keysight-style instrument (module docstring)."""

    identity = "KEYSIGHT TECHNOLOGIES,HOPKINSON-SIM-KS,SIM0002,1.0"
    signed_numbers = True
    hole_code = True
    power_on_channels = (1,)

    def reset(self) -> None:
        with self.lock:
            super().reset()
            self.reference, self.position_s = "CENTer", 0.0
            self.word, self.unsigned, self.points_mode = "BYTE", False, "NORMal"
            self.transfer_points: int | None = 1000  # None: MAXimum
            self.trigger_event = False
            self._transfer_format()
            self._place_trigger()

    def table(self) -> list[tuple[tuple[str, ...], Handler]]:
        return [
            (("SYSTem", "ERRor", "COUNt"), self.system_error_count),
            (("SYSTem", "ERRor"), self.system_error),
            (("ACQuire", "SRATe"), self._sample_rate),
            (("ACQuire", "POINts"), self._points),
            (("TIMebase", "REFerence"), self._reference),
            (("TIMebase", "POSition"), self._position),
            (("CHANnel<n>", "RANGe"), self._range),
            (("CHANnel<n>", "OFFSet"), lambda c: self.zero_only(c, "+0.00000E+00")),
            (("CHANnel<n>", "DISPlay"), self.channel_state),
            (("TRIGger", "MODE"), self.edge_only),
            (("TRIGger", "EDGE", "SOURce"), self._trigger_source),
            (("TRIGger", "EDGE", "LEVel"), self._trigger_level),
            (("TRIGger", "EDGE", "SLOPe"), self._trigger_slope),
            (("SINGle",), self._single),
            (("STOP",), self._stop),
            (("RSTate",), self._run_state),
            (("TER",), self._trigger_event_register),
            (("WAVeform", "SOURce"), self._waveform_source),
            (("WAVeform", "FORMat"), self._format),
            (("WAVeform", "UNSigned"), self._unsigned),
            (("WAVeform", "BYTeorder"), self._byte_order),
            (("WAVeform", "POINts", "MODE"), self._points_mode),
            (("WAVeform", "POINts"), self._transfer_points),
            (("WAVeform", "PREamble"), self._preamble),
            (("WAVeform", "DATA"), self._data),
        ]

    def poll_capture(self) -> None:
        before = self.acquisitions
        super().poll_capture()
        if self.acquisitions > before:
            self.trigger_event = True

    # -- acquisition and timebase ----------------------------------------------------------
    def _place_trigger(self) -> None:
        """The trigger's sample from the reference point and the position."""
        s = self.settings
        index = round(_REFERENCES[self.reference] * s.record_length - self.position_s * s.sample_rate_hz)
        s.pre_trigger_samples = min(max(index, 0), s.record_length - 1)

    def _sample_rate(self, c: Call) -> Reply:
        if c.query:
            return f"{self.settings.sample_rate_hz:+.6E}"
        self.set_sample_rate(self.number(c.arg))
        self._place_trigger()
        return None

    def _points(self, c: Call) -> Reply:
        if c.query:
            return f"{self.settings.record_length:+d}"
        self.set_record_length(self.integer(c.arg))
        self._place_trigger()
        return None

    def _reference(self, c: Call) -> Reply:
        if c.query:
            return {"CENTer": "CENT", "RIGHt": "RIGH"}.get(self.reference, self.reference)
        self.not_while_armed()
        self.reference = self.choice(c.arg, {k: k for k in _REFERENCES})
        self._place_trigger()
        return None

    def _position(self, c: Call) -> Reply:
        if c.query:
            return f"{self.position_s:+.9E}"
        value = self.number(c.arg)
        s = self.settings
        index = _REFERENCES[self.reference] * s.record_length - value * s.sample_rate_hz
        if not -0.5 <= index < s.record_length - 0.5:
            raise SimError(-222, "Data out of range; the trigger must lie inside the record")
        self.not_while_armed()
        self.position_s = value
        self._place_trigger()
        return None

    def _range(self, c: Call) -> Reply:
        channel = self.channel(c.suffix)
        if c.query:
            return f"{2.0 * self.settings.ch_range_v[channel]:+.6E}"
        self.set_range(channel, self.number(c.arg) / 2.0)  # span of 8 divisions -> ±half
        return None

    def _trigger_source(self, c: Call) -> Reply:
        source = self.settings.trigger_source
        if c.query:
            return "EXT" if source == "EXT" else f"CHAN{source[2:]}"
        names = {f"CHANnel{n}": f"CH{n}" for n in range(1, 5)} | {"EXTernal": "EXT"}
        return self.set_trigger(source=self.choice(c.arg, names))

    def _trigger_level(self, c: Call) -> Reply:
        if c.query:
            return f"{self.settings.trigger_level_v:+.6E}"
        return self.set_trigger(level_v=self.number(c.arg))

    def _trigger_slope(self, c: Call) -> Reply:
        if c.query:
            return self.settings.trigger_slope
        return self.set_trigger(slope=self.choice(c.arg, {"POSitive": "POS", "NEGative": "NEG"}))

    def _single(self, c: Call) -> Reply:
        c.command_only()
        self.trigger_event = False
        return self.arm()

    def _stop(self, c: Call) -> Reply:
        c.command_only()
        return self.stop()

    def _run_state(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        return "SING" if self.state == "ARMED" else "STOP"

    def _trigger_event_register(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        event, self.trigger_event = self.trigger_event, False
        return "+1" if event else "+0"

    # -- waveform transfer -------------------------------------------------------------------
    def _transfer_format(self) -> None:
        self.sample_format = ("int" if not self.unsigned else "uint") + ("8" if self.word == "BYTE" else "16")

    def _waveform_source(self, c: Call) -> Reply:
        if c.query:
            return f"CHAN{self.waveform_source}"
        self.waveform_source = self.choice(c.arg, {f"CHANnel{n}": n for n in range(1, 5)})  # type: ignore[assignment]
        return None

    def _format(self, c: Call) -> Reply:
        if c.query:
            return self.word
        self.word = self.choice(c.arg, {"BYTE": "BYTE", "WORD": "WORD"})
        self._transfer_format()
        return None

    def _unsigned(self, c: Call) -> Reply:
        if c.query:
            return "1" if self.unsigned else "0"
        self.unsigned = self.choice(c.arg, {"1": "1", "ON": "1", "0": "0", "OFF": "0"}) == "1"
        self._transfer_format()
        return None

    def _byte_order(self, c: Call) -> Reply:
        if c.query:
            return "LSBF" if self.byte_order == "little" else "MSBF"
        self.byte_order = self.choice(c.arg, {"LSBFirst": "little", "MSBFirst": "big"})
        return None

    def _points_mode(self, c: Call) -> Reply:
        if c.query:
            return self.points_mode.upper()[:4]
        self.points_mode = self.choice(c.arg, {"NORMal": "NORMal", "MAXimum": "MAXimum", "RAW": "RAW"})
        return None

    def _transfer_points(self, c: Call) -> Reply:
        if c.query:
            return f"{self._sent()[1]:+d}"
        if c.arg.strip().upper() in ("MAX", "MAXIMUM"):
            self.transfer_points = None
        else:
            points = self.integer(c.arg)
            self.in_range(points, (100, RECORD_LENGTH_LIMITS[1]))
            self.transfer_points = points
        return None

    def _sent(self) -> tuple[int, int]:
        """(every k-th sample, how many) of the record a transfer sends."""
        n = self.settings.record_length
        if self.transfer_points is None or self.transfer_points >= n:
            return 1, n
        return n // self.transfer_points, self.transfer_points

    def _preamble(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        s = self.settings
        encoded = self.encoded(self.waveform_source)
        step, sent = self._sent()
        points = sent if encoded or self.off_channel(self.waveform_source) else 0
        scale, zero = (encoded[1], encoded[2]) if encoded else (s.ch_range_v[self.waveform_source] / 127, 0.0)
        x_inc = step / s.sample_rate_hz
        fields = [f"{0 if self.word == 'BYTE' else 1:+d}", "+0", f"{points:+d}", "+1", f"{x_inc:+.15E}",
                  f"{-s.pre_trigger_samples / s.sample_rate_hz:+.15E}", "+0", f"{scale:+.9E}", "+0.000000E+00",
                  f"{int(zero):+d}"]
        return ",".join(fields)

    def _data(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        encoded = self.encoded(self.waveform_source)
        if encoded is None and self.off_channel(self.waveform_source):
            self.record_error(-221, "Settings conflict")
            return Block(b"")
        if encoded is None:
            self.record_error(-230, "Data corrupt or stale; no acquisition")
            return Block(b"")
        step, sent = self._sent()
        if step == 1:
            return Block(encoded[0])
        width = 1 if self.word == "BYTE" else 2
        codes = np.frombuffer(encoded[0], dtype=f"u{width}")  # raw words: the byte order is kept
        return Block(codes[::step][:sent].tobytes())
