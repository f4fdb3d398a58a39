"""The simulated generic SCPI digitizer (the dialect of drivers/scpi_dialect.py's
`GenericScpiDialect`); its state, common commands and acquisition are drivers/sim/scpi_instrument.py's.

Commands (short form in capitals):
    :SYSTem:ERRor? (<code>,"<text>"; 0,"No error"), :SYSTem:ERRor:COUNt?
    :ACQuire:SRATe <hz> | ?, :ACQuire:POINts <n> | ?, :ACQuire:PRETrigger <n> | ? (samples)
    :CHANnel<1-4>:RANGe <v> | ?       full scale: the channel reads -v .. +v volts
    :CHANnel<1-4>:DISPlay ON|OFF|1|0 | ?   (1|0; all on after power-on and *RST; the transfer
                                      of an off channel: preamble with 0 points, DATA? refused)
    :TRIGger:SOURce CH<n>|EXT | ?, :TRIGger:LEVel <v> | ?, :TRIGger:SLOPe POS|NEG | ?
    :SINGle, :ABORt, :ACQuire:STATe? (IDLE|ARMED|TRIGGERED)
    :WAVeform:SOURce CH<n> | ?, :WAVeform:FORMat INT8|UINT8|INT16|UINT16|FLOAT32 | ?,
    :WAVeform:BYTeorder LSBF|MSBF | ?
    :WAVeform:PREamble?   <format>,<order>,<points>,<x_increment_s>,<trigger_index>,<y_scale_v>,<y_offset_v>
    :WAVeform:DATA?       IEEE 488.2 definite-length block
"""

from __future__ import annotations

from hopkinson.drivers.sim.scpi_instrument import SimDigitizer
from hopkinson.drivers.sim.scpi_messages import Block, Call, Handler, Reply, SimError


class GenericSimDigitizer(SimDigitizer):
    """The generic SCPI dialect (module docstring)."""

    _FORMATS = {"INT8": "int8", "UINT8": "uint8", "INT16": "int16", "UINT16": "uint16", "FLOAT32": "float32"}
    _ORDERS = {"LSBF": "little", "MSBF": "big"}

    def table(self) -> list[tuple[tuple[str, ...], Handler]]:
        return [
            (("SYSTem", "ERRor", "COUNt"), self.system_error_count),
            (("SYSTem", "ERRor"), self.system_error),
            (("ACQuire", "SRATe"), self._sample_rate),
            (("ACQuire", "POINts"), self._points),
            (("ACQuire", "PRETrigger"), self._pretrigger),
            (("ACQuire", "STATe"), self._state),
            (("CHANnel<n>", "RANGe"), self._range),
            (("CHANnel<n>", "DISPlay"), self.channel_state),
            (("TRIGger", "SOURce"), self._trigger_source),
            (("TRIGger", "LEVel"), self._trigger_level),
            (("TRIGger", "SLOPe"), self._trigger_slope),
            (("SINGle",), self._single),
            (("ABORt",), self._abort),
            (("WAVeform", "SOURce"), self._waveform_source),
            (("WAVeform", "FORMat"), self._format),
            (("WAVeform", "BYTeorder"), self._byte_order),
            (("WAVeform", "PREamble"), self._preamble),
            (("WAVeform", "DATA"), self._data),
        ]

    def _sample_rate(self, c: Call) -> Reply:
        if c.query:
            return repr(float(self.settings.sample_rate_hz))
        return self.set_sample_rate(self.number(c.arg))

    def _points(self, c: Call) -> Reply:
        if c.query:
            return str(self.settings.record_length)
        return self.set_record_length(self.integer(c.arg))

    def _pretrigger(self, c: Call) -> Reply:
        if c.query:
            return str(self.settings.pre_trigger_samples)
        return self.set_pre_trigger(self.integer(c.arg))

    def _state(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        return self.state

    def _range(self, c: Call) -> Reply:
        channel = self.channel(c.suffix)
        if c.query:
            return repr(float(self.settings.ch_range_v[channel]))
        return self.set_range(channel, self.number(c.arg))

    def _trigger_source(self, c: Call) -> Reply:
        if c.query:
            return self.settings.trigger_source
        return self.set_trigger(source=self.choice(c.arg, (*self.channel_names, "EXT")))

    def _trigger_level(self, c: Call) -> Reply:
        if c.query:
            return repr(float(self.settings.trigger_level_v))
        return self.set_trigger(level_v=self.number(c.arg))

    def _trigger_slope(self, c: Call) -> Reply:
        if c.query:
            return self.settings.trigger_slope
        return self.set_trigger(slope=self.choice(c.arg, ("POS", "NEG")))

    def _single(self, c: Call) -> Reply:
        c.command_only()
        return self.arm()

    def _abort(self, c: Call) -> Reply:
        c.command_only()
        self.volts, self._encoded, self.state = {}, {}, "IDLE"
        return None

    def _waveform_source(self, c: Call) -> Reply:
        if c.query:
            return f"CH{self.waveform_source}"
        self.waveform_source = self.channel_names[self.choice(c.arg, tuple(self.channel_names))]
        return None

    def _format(self, c: Call) -> Reply:
        if c.query:
            return {v: k for k, v in self._FORMATS.items()}[self.sample_format]
        self.sample_format = self.choice(c.arg, self._FORMATS)
        return None

    def _byte_order(self, c: Call) -> Reply:
        if c.query:
            return {v: k for k, v in self._ORDERS.items()}[self.byte_order]
        self.byte_order = self.choice(c.arg, self._ORDERS)
        return None

    def _preamble(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        ch = self.waveform_source
        fmt = {v: k for k, v in self._FORMATS.items()}[self.sample_format]
        order = {v: k for k, v in self._ORDERS.items()}[self.byte_order]
        encoded = self.encoded(ch)
        points = 0 if encoded is None else self.settings.record_length
        scale, zero = (encoded[1], encoded[2]) if encoded else (self.settings.ch_range_v[ch] / 32767, 0.0)
        return (f"{fmt},{order},{points},{1.0 / self.settings.sample_rate_hz!r},"
                f"{self.settings.pre_trigger_samples},{scale!r},{-zero * scale!r}")

    def _data(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        encoded = self.encoded(self.waveform_source)
        if encoded is None and self.off_channel(self.waveform_source):
            raise SimError(-221, f"Settings conflict; CH{self.waveform_source} is off: not acquired")
        if encoded is None:
            raise SimError(-230, "Data corrupt or stale; no acquisition")
        return Block(encoded[0])

