"""Tektronix-style oscilloscopes (MSO/DPO series) as the rig's digitizer.

Commands (Tektronix programmer manuals; replies with HEADer OFF unless said otherwise):
    HEADer OFF, VERBose ON                      replies carry no headers
    HORizontal:MODE MANual, HORizontal:MODE:SAMPLERate <rate>, HORizontal:MODE:RECOrdlength <n>
    HORizontal:DELay:MODe OFF, HORizontal:POSition <percent>   the trigger sits <percent> of the
                                                record from its start: pre-trigger = % · record
    CH<n>:SCAle <volts/div>                     10 divisions: a ±10 V channel is 2 V/div
    SELect:CH<n> ON | ? (1|0)                   a channel that is off is not acquired (the
                                                default setup shows CH1 only; CURVe? of an off
                                                source is refused: "source waveform is not active")
    CH<n>:OFFSet 0, CH<n>:POSition 0
    TRIGger:A:TYPe EDGE, TRIGger:A:EDGE:SOUrce CH<n>|AUXiliary, TRIGger:A:LEVel:CH<n> <v>,
    TRIGger:A:EDGE:SLOpe RISe|FALL
    ACQuire:STOPAfter SEQuence, ACQuire:STATE RUN|STOP, ACQuire:STATE? (1 running, 0 stopped),
    ACQuire:NUMACq? (acquisitions since the last RUN)
    DATa:SOUrce CH<n>, DATa:ENCdg RIBinary|RPBinary|FPBinary (MSB first) or SRIbinary|SRPbinary|
    SFPbinary (LSB first, "swapped"), DATa:WIDth 1|2|4, DATa:STARt 1, DATa:STOP <n>, CURVe? (block)
    WFMOutpre? (with HEADer ON: "KEY value" pairs, in whatever order and number the model has):
        BYT_NR, BN_FMT (RI|RP|FP), BYT_OR (LSB|MSB), NR_PT, XINCR, XZERO, PT_OFF, YMULT, YOFF, YZERO
        time = XZERO + XINCR·(i − PT_OFF); volts = (code − YOFF)·YMULT + YZERO
    errors: *ESR? (command/execution/device/query error bits) then ALLEv? (<code>,"<text>",...)

Message units after the first start with ':' (a new root), as Tektronix concatenation wants.
"""

from __future__ import annotations

from hopkinson.drivers.digitizer_settings import DigitizerSettings, pre_trigger_samples
from hopkinson.drivers.digitizer_waveform import Waveform, sample_dtype
from hopkinson.drivers.scpi_dialect import (
    CommandRefused,
    DigitizerDialect,
    ReplyFormatError,
    ScpiLink,
    split_outside_quotes,
)

DIVISIONS = 10  # vertical divisions on screen: ±5 around the centre
_ENCODINGS = {  # (sample format, byte order) -> DATa:ENCdg, DATa:WIDth
    ("int8", "little"): ("RIBinary", 1), ("int8", "big"): ("RIBinary", 1),
    ("uint8", "little"): ("RPBinary", 1), ("uint8", "big"): ("RPBinary", 1),
    ("int16", "little"): ("SRIbinary", 2), ("int16", "big"): ("RIBinary", 2),
    ("uint16", "little"): ("SRPbinary", 2), ("uint16", "big"): ("RPBinary", 2),
    ("float32", "little"): ("SFPbinary", 4), ("float32", "big"): ("FPBinary", 4),
}
_SLOPES = {"POS": "RISe", "NEG": "FALL"}
_ESR_ERRORS = 0b0011_1100  # command, execution, device-dependent and query error bits


class TektronixDialect(DigitizerDialect):
    """Tektronix-style commands and replies (module docstring)."""

    name = "tektronix"
    channel_names = ("CH1", "CH2", "CH3", "CH4")
    external_trigger = "AUX"

    def join(self, *units: str) -> str:
        return ";".join(u if i == 0 or u.startswith((":", "*")) else ":" + u for i, u in enumerate(units))

    def command(self, link: ScpiLink, *units: str) -> None:
        """Send commands, then *ESR? and ALLEv? in the same message; raise if an error bit is set."""
        command = self.join(*units)
        reply = link.query(self.join("*CLS", command, "*ESR?", "ALLEv?"))
        esr_text, _, events = reply.partition(";")
        esr = self.integer(command, esr_text, reply)
        if esr & _ESR_ERRORS:
            raise CommandRefused(command, f"refused by the instrument (*ESR? {esr}: {events.strip()})", reply)

    def prepare(self, link: ScpiLink) -> None:
        encoding, width = _ENCODINGS[(self.transfer.sample_format, self.transfer.byte_order)]
        self.command(link, "HEADer OFF", "VERBose ON", f"DATa:ENCdg {encoding}", f"DATa:WIDth {width:d}",
                     "DATa:STARt 1")

    def apply(self, link: ScpiLink, settings: DigitizerSettings) -> None:
        percent = 100.0 * settings.pre_trigger_samples / settings.record_length
        units = self.turn_on_units(settings)
        units += ["HORizontal:MODE MANual", f"HORizontal:MODE:SAMPLERate {settings.sample_rate_hz:.6E}",
                  f"HORizontal:MODE:RECOrdlength {settings.record_length:d}", "HORizontal:DELay:MODe OFF",
                  f"HORizontal:POSition {percent:.6f}", f"DATa:STOP {settings.record_length:d}"]
        for ch, range_v in settings.ranges_v.items():
            units += [f"{ch}:SCAle {float(range_v) * 2 / DIVISIONS:.6E}", f"{ch}:OFFSet 0", f"{ch}:POSition 0"]
        units += ["TRIGger:A:TYPe EDGE", f"TRIGger:A:EDGE:SOUrce {self._source(settings.trigger_source)}",
                  f"TRIGger:A:EDGE:SLOpe {_SLOPES[settings.trigger_slope]}"]
        if settings.trigger_source != self.external_trigger:
            units.append(f"TRIGger:A:LEVel:{settings.trigger_source} {float(settings.trigger_level_v):.6E}")
        else:
            units.append(f"TRIGger:A:LEVel:AUXiliary {float(settings.trigger_level_v):.6E}")
        self.command(link, *units)

    def _source(self, name: str) -> str:
        return "AUXiliary" if name == self.external_trigger else name

    def read_settings(self, link: ScpiLink, context: DigitizerSettings) -> DigitizerSettings:
        channels = context.channels
        units = ["HORizontal:MODE:SAMPLERate?", "HORizontal:MODE:RECOrdlength?", "HORizontal:POSition?"]
        units += [f"{ch}:SCAle?" for ch in channels]
        units += ["TRIGger:A:EDGE:SOUrce?", "TRIGger:A:EDGE:SLOpe?"]
        command = self.join(*units)
        fields = self.query_fields(link, units)
        rate, points = self.number(command, fields[0]), self.integer(command, fields[1])
        percent = self.number(command, fields[2])
        n = len(channels)
        source_text = fields[3 + n].upper()
        source = self.external_trigger if source_text.startswith("AUX") else self.channel_name(source_text)
        slope = {"RIS": "POS", "FAL": "NEG"}.get(fields[4 + n].upper()[:3])
        if slope is None:
            raise ReplyFormatError(command, f"unknown trigger slope {fields[4 + n]!r}", self.join(*fields))
        level_query = f"TRIGger:A:LEVel:{'AUXiliary' if source == self.external_trigger else source}?"
        level = self.number(level_query, link.query(level_query))
        held = DigitizerSettings(
            sample_rate_hz=rate, record_length=points,
            pre_trigger_samples=pre_trigger_samples(percent / 100.0, points),
            ranges_v={ch: self.number(command, f) * DIVISIONS / 2 for ch, f in zip(channels, fields[3:3 + n],
                                                                                     strict=True)},
            trigger_source=source, trigger_level_v=level, trigger_slope=slope,
        )
        return self.with_channels_on(link, held, context)

    def on_command(self, channel: str) -> str | None:
        return f"SELect:{channel} ON"

    def on_query(self, channel: str) -> str | None:
        return f"SELect:{channel}?"

    def arm(self, link: ScpiLink) -> None:
        self.command(link, "ACQuire:STOPAfter SEQuence", "ACQuire:STATE RUN")

    def abort(self, link: ScpiLink) -> None:
        self.command(link, "ACQuire:STATE STOP")

    def state(self, link: ScpiLink) -> str:
        units = ["ACQuire:STATE?", "ACQuire:NUMACq?"]
        command = self.join(*units)
        running, count = (self.integer(command, f) for f in self.query_fields(link, units))
        return "ARMED" if running else ("TRIGGERED" if count > 0 else "IDLE")

    def fetch(self, link: ScpiLink, channel: str, context: DigitizerSettings) -> Waveform:
        units = [f"DATa:SOUrce {channel}", "HEADer ON", "WFMOutpre?", "HEADer OFF", f"{channel}:SCAle?"]
        command = self.join(*units)
        reply = link.query(command)
        fields = split_outside_quotes(reply, ";")
        pre = self._preamble_fields(command, reply, fields[:-1])
        scale_per_div = self.number(command, fields[-1], reply)

        def value(key: str) -> str:
            if key not in pre:
                raise ReplyFormatError(command, f"preamble has no {key}", reply)
            return pre[key]

        width, points = self.integer(command, value("BYT_NR"), reply), self.integer(command, value("NR_PT"), reply)
        kind, order = value("BN_FMT").upper(), value("BYT_OR").upper()
        base = {"RI": "int", "RP": "uint", "FP": "float"}.get(kind)
        if base is None or order not in ("LSB", "MSB") or (base == "float") != (width == 4) or width not in (1, 2, 4):
            raise ReplyFormatError(command, f"unsupported waveform encoding ({kind}, {width} bytes, {order})", reply)
        sample_format = f"{base}{8 * width}"
        x_inc, x_zero = self.number(command, value("XINCR"), reply), self.number(command, value("XZERO"), reply)
        pt_off = self.number(command, value("PT_OFF"), reply)
        y_mult, y_off, y_zero = (self.number(command, value(k), reply) for k in ("YMULT", "YOFF", "YZERO"))
        return self.fetch_samples(link, "CURVe?", channel, context, preamble=(command, reply), points=points,
                                  dtype=sample_dtype(sample_format, "little" if order == "LSB" else "big"),
                                  scale_v=y_mult, offset_v=y_zero - y_off * y_mult, sample_interval_s=x_inc,
                                  trigger_index=int(round(pt_off - x_zero / x_inc)),
                                  range_v=scale_per_div * DIVISIONS / 2)

    @staticmethod
    def _preamble_fields(command: str, reply: str, fields: list[str]) -> dict[str, str]:
        """{"BYT_NR": "2", ...} from ':WFMOUTPRE:BYT_NR 2;BIT_NR 16;...' (last header node, value)."""
        out: dict[str, str] = {}
        for field in fields:
            header, _, value = field.partition(" ")
            key = header.rsplit(":", 1)[-1].upper()
            if not key or not value:
                raise ReplyFormatError(command, f"preamble field without a header: {field!r}", reply)
            out[key] = value.strip()
        return out
