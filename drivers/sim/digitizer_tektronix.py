"""Simulated Tektronix-style oscilloscope (MSO/DPO series; its side of the protocol).

Written from the Tektronix programmer manuals, independently of drivers/digitizer_tektronix.py.
After *RST replies carry headers (HEADer ON, VERBose ON: ":HORIZONTAL:RECORDLENGTH 100000");
HEADer OFF leaves the bare values. Errors go to the event queue as Tektronix does it: an error
sets its *ESR? bit, and *ESR? moves the pending events to the queue that EVENT?, EVMsg? and
ALLEv? read (codes 1xx command errors, 2xx execution errors, 3xx device errors).

    HEADer ON|OFF | ?, VERBose ON|OFF | ?
    HORizontal:MODE AUTO|CONStant|MANual | ?, HORizontal:MODE:SAMPLERate <r> | ?,
    HORizontal:MODE:RECOrdlength <n> | ?, HORizontal:DELay:MODe ON|OFF | ?,
    HORizontal:POSition <percent> | ?        the trigger at that % of the record (delay off)
    CH<n>:SCAle <V/div> | ?                  10 divisions: the channel reads ±5·scale
    CH<n>:OFFSet <v> | ?, CH<n>:POSition <div> | ?   (only 0 is simulated)
    SELect:CH<n> ON|OFF|1|0 | ? (1|0)        the default setup (*RST) shows CH1 only; a channel
                                             that is off is not acquired: its preamble has 0
                                             points and CURVe? is refused (event 221, "source
                                             waveform is not active") with an empty block
    TRIGger:A:TYPe EDGE | ?, TRIGger:A:EDGE:SOUrce CH<n>|AUXiliary | ?,
    TRIGger:A:LEVel:CH<n>|AUXiliary <v> | ? (one level per source), TRIGger:A:EDGE:SLOpe
    RISe|FALL | ?, TRIGger:STATE? (ARMED while armed, SAVE when stopped)
    ACQuire:STOPAfter RUNSTop|SEQuence | ?, ACQuire:STATE RUN|STOP|ON|OFF|1|0 | ? (1/0),
    ACQuire:NUMACq? (acquisitions since the last RUN)
    DATa:SOUrce CH<n> | ?, DATa:ENCdg RIBinary|RPBinary|FPBinary|SRIbinary|SRPbinary|SFPbinary
    | ?, DATa:WIDth 1|2|4 | ?, DATa:STARt <n> | ?, DATa:STOP <n> | ?
    WFMOutpre? (all fields) and WFMOutpre:<field>? (BYT_Nr, BIT_Nr, ENCdg, BN_Fmt, BYT_Or,
    WFId, NR_Pt, PT_Fmt, XUNit, XINcr, XZEro, PT_Off, YUNit, YMUlt, YOFf, YZEro)
    CURVe?  the samples DATa:STARt..DATa:STOP as a block
    EVENT?, EVMsg?, ALLEv?
"""

from __future__ import annotations

from collections.abc import Callable

from hopkinson.drivers.sim.scpi_instrument import SimDigitizer
from hopkinson.drivers.sim.scpi_messages import Block, Call, Handler, Reply, SimError, long_header

DIVISIONS = 10
_ENCODINGS = {  # DATa:ENCdg -> (binary format, byte order)
    "RIBinary": ("RI", "big"), "RPBinary": ("RP", "big"), "FPBinary": ("FP", "big"),
    "SRIbinary": ("RI", "little"), "SRPbinary": ("RP", "little"), "SFPbinary": ("FP", "little"),
}
_MESSAGES = {113: "Undefined header; Command not found", 104: "Data type error", 108: "Parameter not allowed",
             109: "Missing parameter", 114: "Header suffix out of range", 221: "Settings conflict",
             222: "Data out of range", 224: "Illegal parameter value", 230: "Data corrupt or stale",
             240: "Hardware error"}


class TektronixSimDigitizer(SimDigitizer):
    """The simulated Tektronix-style instrument (module docstring)."""

    identity = "TEKTRONIX,HOPKINSON-SIM-TEK,SIM0003,CF:91.1CT FV:1.0"
    power_on_channels = (1,)

    def __init__(self, *args: object, **kwargs: object) -> None:
        self.pending_events: list[tuple[int, str]] = []  # errors until *ESR? is read
        self.events: list[tuple[int, str]] = []  # what EVENT?, EVMsg?, ALLEv? read
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def reset(self) -> None:
        with self.lock:
            super().reset()
            self.header, self.verbose = True, True
            self.horizontal_mode, self.delay_mode, self.position_pct = "AUTO", "OFF", 10.0
            self.stop_after = "RUNSTop"
            self.levels = {"CH1": 0.0, "CH2": 0.0, "CH3": 0.0, "CH4": 0.0, "EXT": 0.0}
            self.encoding, self.width, self.start, self.stop_point = "RIBinary", 1, 1, 10_000
            self.settings.trigger_source, self.settings.trigger_level_v = "CH1", 0.0
            self._place_trigger()

    def table(self) -> list[tuple[tuple[str, ...], Handler]]:
        h = self._headed
        rows: list[tuple[tuple[str, ...], Handler]] = [
            (("HEADer",), h(self._header)),
            (("VERBose",), h(self._verbose)),
            (("HORizontal", "MODE"), h(self._horizontal_mode)),
            (("HORizontal", "MODE", "SAMPLERate"), h(self._sample_rate)),
            (("HORizontal", "SAMPLERate"), h(self._sample_rate)),
            (("HORizontal", "MODE", "RECOrdlength"), h(self._record_length)),
            (("HORizontal", "RECOrdlength"), h(self._record_length)),
            (("HORizontal", "DELay", "MODe"), h(self._delay_mode)),
            (("HORizontal", "POSition"), h(self._position)),
            (("CH<n>", "SCAle"), h(self._scale)),
            (("SELect", "CH<n>"), h(self.channel_state)),
            (("CH<n>", "OFFSet"), h(lambda c: self.zero_only(c, "0.0E+0"))),
            (("CH<n>", "POSition"), h(lambda c: self.zero_only(c, "0.0E+0"))),
            (("TRIGger", "A", "TYPe"), h(self.edge_only)),
            (("TRIGger", "A", "EDGE", "SOUrce"), h(self._trigger_source)),
            (("TRIGger", "A", "LEVel", "CH<n>"), h(self._level)),
            (("TRIGger", "A", "LEVel", "AUXiliary"), h(self._level)),
            (("TRIGger", "A", "EDGE", "SLOpe"), h(self._trigger_slope)),
            (("TRIGger", "STATE"), h(self._trigger_state)),
            (("ACQuire", "STOPAfter"), h(self._stop_after)),
            (("ACQuire", "STATE"), h(self._acquire_state)),
            (("ACQuire", "NUMACq"), h(self._numacq)),
            (("DATa", "SOUrce"), h(self._data_source)),
            (("DATa", "ENCdg"), h(self._encoding)),
            (("DATa", "WIDth"), h(self._width)),
            (("DATa", "STARt"), h(self._start)),
            (("DATa", "STOP"), h(self._stop)),
            (("WFMOutpre",), self._preamble),
            (("CURVe",), self._curve),
            (("EVENT",), h(self._event)),
            (("EVMsg",), h(self._evmsg)),
            (("ALLEv",), h(self._allev)),
        ]
        rows += [(("WFMOutpre", key), h(self._preamble_field)) for key in _FIELDS]
        return rows

    def _headed(self, handler: Handler) -> Callable[[Call], Reply]:
        """A query's reply with its header while HEADer is ON."""
        def run(c: Call) -> Reply:
            reply = handler(c)
            if isinstance(reply, str) and self.header:
                return f"{long_header(c)} {reply}"
            return reply
        return run

    # -- events (Tektronix status reporting) ---------------------------------------------------
    def record_error(self, code: int, message: str) -> None:
        self.esr |= self.esr_bit(code)  # Tektronix queues events, not SCPI errors
        if len(self.pending_events) < 32:
            self.pending_events.append((abs(code), message.replace('"', "'")))

    def clear_status(self) -> None:
        self.pending_events, self.events = [], []

    def _common(self, header: str, query: bool, arg: str, replies: list[str | Block]) -> Reply:
        if header == "*ESR" and query:  # reading the register makes its events readable
            self.events, self.pending_events = self.events + self.pending_events, []
        return super()._common(header, query, arg, replies)

    def status_byte(self, message_available: bool) -> int:
        stb = super().status_byte(message_available)
        return stb | (0x04 if self.events or self.pending_events else 0)

    def _event_text(self, code: int, message: str) -> str:
        base = _MESSAGES.get(code, message.partition(";")[0])
        return f'{code},"{base}; {message.partition(";")[2].strip() or message}"'

    def _no_events(self) -> str:
        if self.pending_events:
            return '1,"No events to report - new events pending *ESR?"'
        return '0,"No events to report - queue empty"'

    def _event(self, c: Call) -> Reply:
        c.query_only()
        return str(self.events.pop(0)[0]) if self.events else self._no_events().partition(",")[0]

    def _evmsg(self, c: Call) -> Reply:
        c.query_only()
        return self._event_text(*self.events.pop(0)) if self.events else self._no_events()

    def _allev(self, c: Call) -> Reply:
        c.query_only()
        events, self.events = self.events, []
        return ",".join(self._event_text(*e) for e in events) if events else self._no_events()

    @staticmethod
    def _query_only(c: Call) -> None:
        c.query_only()

    # -- settings -----------------------------------------------------------------------------
    def _on_off(self, c: Call, attr: str) -> Reply:
        if c.query:
            return "1" if getattr(self, attr) else "0"
        setattr(self, attr, self.choice(c.arg, {"ON": "1", "1": "1", "OFF": "0", "0": "0"}) == "1")
        return None

    def _header(self, c: Call) -> Reply:
        return self._on_off(c, "header")

    def _verbose(self, c: Call) -> Reply:
        return self._on_off(c, "verbose")

    def _horizontal_mode(self, c: Call) -> Reply:
        if c.query:
            return self.horizontal_mode.upper()[:4] if self.horizontal_mode != "MANual" else "MANUAL"
        self.horizontal_mode = self.choice(c.arg, {"AUTO": "AUTO", "CONStant": "CONStant", "MANual": "MANual"})
        return None

    def _place_trigger(self) -> None:
        s = self.settings
        s.pre_trigger_samples = min(max(round(self.position_pct / 100.0 * s.record_length), 0), s.record_length - 1)

    def _sample_rate(self, c: Call) -> Reply:
        if c.query:
            return f"{self.settings.sample_rate_hz:.9E}"
        self.set_sample_rate(self.number(c.arg))
        return None

    def _record_length(self, c: Call) -> Reply:
        if c.query:
            return str(self.settings.record_length)
        self.set_record_length(self.integer(c.arg))
        self._place_trigger()
        return None

    def _delay_mode(self, c: Call) -> Reply:
        if c.query:
            return "1" if self.delay_mode == "ON" else "0"
        self.delay_mode = self.choice(c.arg, {"ON": "ON", "1": "ON", "OFF": "OFF", "0": "OFF"})
        return None

    def _position(self, c: Call) -> Reply:
        if c.query:
            return f"{self.position_pct:.6f}"
        value = self.number(c.arg)
        self.in_range(value, (0.0, 100.0))
        if self.delay_mode == "ON":
            raise SimError(-221, "Settings conflict; horizontal delay mode is on")
        self.not_while_armed()
        self.position_pct = value
        self._place_trigger()
        return None

    def _scale(self, c: Call) -> Reply:
        channel = self.channel(c.suffix)
        if c.query:
            return f"{self.settings.ch_range_v[channel] * 2 / DIVISIONS:.6E}"
        self.set_range(channel, self.number(c.arg) * DIVISIONS / 2)
        return None

    def _trigger_source(self, c: Call) -> Reply:
        source = self.settings.trigger_source
        if c.query:
            return "AUXILIARY" if source == "EXT" else source
        names = {f"CH{n}": f"CH{n}" for n in range(1, 5)} | {"AUXiliary": "EXT"}
        new = self.choice(c.arg, names)
        return self.set_trigger(source=new, level_v=self.levels[new])

    def _level(self, c: Call) -> Reply:
        source = f"CH{self.channel(c.suffix)}" if c.suffixes else "EXT"
        if c.query:
            return f"{self.levels[source]:.6E}"
        value = self.number(c.arg)
        self.in_range(abs(value), (0.0, 100.0))
        self.not_while_armed()
        self.levels[source] = value
        if source == self.settings.trigger_source:
            self.settings.trigger_level_v = value
        return None

    def _trigger_slope(self, c: Call) -> Reply:
        if c.query:
            return "RISE" if self.settings.trigger_slope == "POS" else "FALL"
        return self.set_trigger(slope=self.choice(c.arg, {"RISe": "POS", "FALL": "NEG"}))

    def _trigger_state(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        return "ARMED" if self.state == "ARMED" else "SAVE"

    def _stop_after(self, c: Call) -> Reply:
        if c.query:
            return "SEQUENCE" if self.stop_after == "SEQuence" else "RUNSTOP"
        self.stop_after = self.choice(c.arg, {"RUNSTop": "RUNSTop", "SEQuence": "SEQuence"})
        return None

    def _acquire_state(self, c: Call) -> Reply:
        if c.query:
            self.poll_capture()
            return "1" if self.state == "ARMED" else "0"
        run = self.choice(c.arg, {"RUN": "1", "ON": "1", "1": "1", "STOP": "0", "OFF": "0", "0": "0"}) == "1"
        return self.arm() if run else self.stop()

    def _numacq(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        return str(self.acquisitions)

    # -- waveform transfer ----------------------------------------------------------------------
    def _data_source(self, c: Call) -> Reply:
        if c.query:
            return f"CH{self.waveform_source}"
        self.waveform_source = int(self.choice(c.arg, {f"CH{n}": str(n) for n in range(1, 5)}))
        return None

    def _encoding(self, c: Call) -> Reply:
        if c.query:
            return self.encoding.upper()
        self.encoding = self.choice(c.arg, {k: k for k in _ENCODINGS})
        return None

    def _width(self, c: Call) -> Reply:
        if c.query:
            return str(self.width)
        self.width = int(self.choice(c.arg, ("1", "2", "4")))
        return None

    def _start(self, c: Call) -> Reply:
        if c.query:
            return str(self.start)
        self.start = max(1, self.integer(c.arg))
        return None

    def _stop(self, c: Call) -> Reply:
        if c.query:
            return str(self.stop_point)
        self.stop_point = max(1, self.integer(c.arg))
        return None

    def _format(self) -> tuple[str, str, str]:
        """(sample format, BN_FMT, byte order) of the current DATa settings."""
        kind, order = _ENCODINGS[self.encoding]
        valid = {("RI", 1): "int8", ("RI", 2): "int16", ("RP", 1): "uint8", ("RP", 2): "uint16", ("FP", 4): "float32"}
        fmt = valid.get((kind, self.width))
        if fmt is None:
            raise SimError(-221, f"Settings conflict; {self.encoding} with DATa:WIDth {self.width}")
        return fmt, kind, order

    def _span(self) -> tuple[int, int]:
        """First sample and count of the transfer (DATa:STARt..STOP within the record)."""
        n = self.settings.record_length
        first = min(self.start, n) - 1
        return first, max(0, min(self.stop_point, n) - first)

    def _preamble_values(self) -> dict[str, str]:
        self.poll_capture()
        fmt, kind, order = self._format()
        self.sample_format, self.byte_order = fmt, order
        ch, s = self.waveform_source, self.settings
        encoded = self.encoded(ch)
        first, count = self._span()
        points = count if encoded else 0
        scale, zero = (encoded[1], encoded[2]) if encoded else (s.ch_range_v[ch] / 32767, 0.0)
        x_inc = 1.0 / s.sample_rate_hz
        return {
            "BYT_NR": str(self.width), "BIT_NR": str(8 * self.width), "ENCDG": "BINARY", "BN_FMT": kind,
            "BYT_OR": "LSB" if order == "little" else "MSB",
            "WFID": f'"Ch{ch}, DC coupling, {s.ch_range_v[ch] * 2 / DIVISIONS:.4g}V/div, {points} points, Sample mode"',
            "NR_PT": str(points), "PT_FMT": "Y", "XUNIT": '"s"', "XINCR": f"{x_inc:.9E}",
            "XZERO": f"{(first - s.pre_trigger_samples) * x_inc:.9E}", "PT_OFF": "0", "YUNIT": '"V"',
            "YMULT": f"{scale:.9E}", "YOFF": f"{zero:.6E}", "YZERO": "0.0E+0",
        }

    def _preamble(self, c: Call) -> Reply:
        c.query_only()
        values = self._preamble_values()
        if not self.header:
            return ";".join(values.values())
        parts = [f"{key} {value}" for key, value in values.items()]
        return ":WFMOUTPRE:" + ";".join(parts)

    def _preamble_field(self, c: Call) -> Reply:
        c.query_only()
        return self._preamble_values()[_FIELDS[c.nodes[1]]]

    def _curve(self, c: Call) -> Reply:
        c.query_only()
        self.poll_capture()
        fmt, _, order = self._format()
        self.sample_format, self.byte_order = fmt, order
        encoded = self.encoded(self.waveform_source)
        if encoded is None and self.off_channel(self.waveform_source):
            self.record_error(-221, "Settings conflict; source waveform is not active")
            return Block(b"")
        if encoded is None:
            self.record_error(-230, "Data corrupt or stale; no acquisition")
            return Block(b"")
        first, count = self._span()
        size = encoded[0]
        itemsize = len(size) // self.settings.record_length
        return Block(memoryview(size)[first * itemsize:(first + count) * itemsize])


_FIELDS = {"BYT_Nr": "BYT_NR", "BIT_Nr": "BIT_NR", "ENCdg": "ENCDG", "BN_Fmt": "BN_FMT", "BYT_Or": "BYT_OR",
           "WFId": "WFID", "NR_Pt": "NR_PT", "PT_Fmt": "PT_FMT", "XUNit": "XUNIT", "XINcr": "XINCR",
           "XZEro": "XZERO", "PT_Off": "PT_OFF", "YUNit": "YUNIT", "YMUlt": "YMULT", "YOFf": "YOFF",
           "YZEro": "YZERO"}
