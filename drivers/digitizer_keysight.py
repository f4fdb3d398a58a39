"""Keysight InfiniiVision/Infiniium-style oscilloscopes as the rig's digitizer.

Commands (Keysight programmer's guides; short forms in capitals):
    :ACQuire:SRATe <rate>, :ACQuire:POINts <n>        sample rate and memory depth (Infiniium-style)
    :TIMebase:REFerence LEFT, :TIMebase:POSition <s>  the trigger sits <s> after the left edge when
                                                      <s> is negative: pre-trigger = −position·rate
    :CHANnel<n>:RANGe <v>                             the FULL vertical span (8 divisions): a ±10 V
                                                      channel is RANGe 20
    :CHANnel<n>:DISPlay ON | ? (1|0)                  a channel that is off is not acquired (after
                                                      power-on or *RST only channel 1 is on; a
                                                      transfer of an off channel is an empty block)
    :TRIGger:MODE EDGE, :TRIGger:EDGE:SOURce CHANnel<n>|EXTernal, :TRIGger:EDGE:LEVel <v>,
    :TRIGger:EDGE:SLOPe POSitive|NEGative
    :SINGle (arm one acquisition), :STOP, :RSTate? (RUN|STOP|SING), :TER? (trigger event
    register: 1 once after a trigger, cleared by reading)
    :WAVeform:SOURce CHANnel<n>, :WAVeform:FORMat BYTE|WORD, :WAVeform:UNSigned 0|1,
    :WAVeform:BYTeorder LSBFirst|MSBFirst, :WAVeform:POINts:MODE RAW, :WAVeform:POINts MAXimum
    (the whole record: the instrument's default sends the screen's 1000 points), :WAVeform:DATA?
    (block; codes 0x00/0x0000 a hole, 0x01/0x0001 clipped low, 0xFF/0xFFFF clipped high, each
    shifted by half the range when signed: the full-scale codes are one above the format's lowest)
    :WAVeform:PREamble? -> format (0 BYTE, 1 WORD, 4 ASCii), type, points, count, xincrement,
                           xorigin, xreference, yincrement, yorigin, yreference
                           time = (i − xreference)·xincrement + xorigin
                           volts = (code − yreference)·yincrement + yorigin
    errors: :SYSTem:ERRor? -> +0,"No error"

Families. The acquisition commands are Infiniium's (:ACQuire:SRATe and :ACQuire:POINts set the
rate and memory depth); the trigger and transfer commands are InfiniiVision's (:TRIGger:EDGE:LEVel,
:WAVeform:POINts:MODE, :WAVeform:UNSigned). An instrument that lacks one answers with an error in
its queue, which the driver reports naming the command (nothing is silently ignored); a lab with
such an instrument derives its own dialect from this class and overrides `apply`/`prepare`.

State: :RSTate? says SING while the single acquisition waits and STOP once done (or stopped);
:TER? tells the two apart. Because reading :TER? clears it, the dialect latches a trigger it
has seen until the next :SINGle or :STOP (DigitizerDialect.latched_state).
"""

from __future__ import annotations

from hopkinson.drivers.digitizer_settings import DigitizerSettings, pre_trigger_samples
from hopkinson.drivers.digitizer_waveform import Waveform, integer_rails, sample_dtype
from hopkinson.drivers.scpi_dialect import ReplyFormatError, ScpiErrorQueueDialect, ScpiLink

_FORMATS = {"int8": ("BYTE", 0), "uint8": ("BYTE", 1), "int16": ("WORD", 0), "uint16": ("WORD", 1)}
_ORDERS = {"little": "LSBFirst", "big": "MSBFirst"}
_SLOPES = {"POS": "POSitive", "NEG": "NEGative"}


class KeysightDialect(ScpiErrorQueueDialect):
    """Keysight-style commands and replies (module docstring)."""

    name = "keysight"
    channel_names = ("CHAN1", "CHAN2", "CHAN3", "CHAN4")
    external_trigger = "EXT"
    sample_formats = tuple(_FORMATS)

    channel_prefix = "CHAN"

    def _source(self, name: str) -> str:
        return "EXTernal" if name == self.external_trigger else f"CHANnel{self.channel_number(name):d}"

    def prepare(self, link: ScpiLink) -> None:
        word, unsigned = _FORMATS[self.transfer.sample_format]
        self.command(link, ":WAVeform:POINts:MODE RAW", ":WAVeform:POINts MAXimum", f":WAVeform:FORMat {word}",
                     f":WAVeform:UNSigned {unsigned:d}", f":WAVeform:BYTeorder {_ORDERS[self.transfer.byte_order]}")

    def apply(self, link: ScpiLink, settings: DigitizerSettings) -> None:
        position_s = -settings.pre_trigger_samples / settings.sample_rate_hz
        units = self.turn_on_units(settings)
        units += [f":ACQuire:SRATe {settings.sample_rate_hz:.6E}", f":ACQuire:POINts {settings.record_length:d}",
                  ":TIMebase:REFerence LEFT", f":TIMebase:POSition {position_s:.9E}"]
        units += [f":CHANnel{self.channel_number(ch):d}:RANGe {2.0 * float(r):.6E}"
                  for ch, r in settings.ranges_v.items()]
        units += [":TRIGger:MODE EDGE", f":TRIGger:EDGE:SOURce {self._source(settings.trigger_source)}",
                  f":TRIGger:EDGE:LEVel {float(settings.trigger_level_v):.6E}",
                  f":TRIGger:EDGE:SLOPe {_SLOPES[settings.trigger_slope]}"]
        self.command(link, *units)

    def read_settings(self, link: ScpiLink, context: DigitizerSettings) -> DigitizerSettings:
        channels = context.channels
        units = [":ACQuire:SRATe?", ":ACQuire:POINts?", ":TIMebase:REFerence?", ":TIMebase:POSition?"]
        units += [f":CHANnel{self.channel_number(ch):d}:RANGe?" for ch in channels]
        units += [":TRIGger:EDGE:SOURce?", ":TRIGger:EDGE:LEVel?", ":TRIGger:EDGE:SLOPe?"]
        command = self.join(*units)
        fields = self.query_fields(link, units)
        rate = self.number(command, fields[0])
        points = self.integer(command, fields[1])
        if fields[2].upper() != "LEFT":
            raise ReplyFormatError(command, f"the timebase reference is {fields[2]!r}, not LEFT: the pre-trigger "
                                            "cannot be read from the position", self.join(*fields))
        pre = pre_trigger_samples(max(0.0, -self.number(command, fields[3]) * rate / points), points)
        n = len(channels)
        spans = [self.number(command, f) for f in fields[4:4 + n]]
        source = fields[4 + n].upper()
        source = self.external_trigger if source.startswith("EXT") else self.channel_name(source)
        slope = {"POS": "POS", "NEG": "NEG"}.get(fields[6 + n].upper()[:3], fields[6 + n].upper())
        held = DigitizerSettings(
            sample_rate_hz=rate, record_length=points, pre_trigger_samples=pre,
            ranges_v={ch: span / 2.0 for ch, span in zip(channels, spans, strict=True)},  # span -> ±range
            trigger_source=source, trigger_level_v=self.number(command, fields[5 + n]), trigger_slope=slope,
        )
        return self.with_channels_on(link, held, context)

    def on_command(self, channel: str) -> str | None:
        return f":CHANnel{self.channel_number(channel):d}:DISPlay ON"

    def on_query(self, channel: str) -> str | None:
        return f":CHANnel{self.channel_number(channel):d}:DISPlay?"

    def arm(self, link: ScpiLink) -> None:
        self.forget_completion()
        self.command(link, ":SINGle")

    def abort(self, link: ScpiLink) -> None:
        self.forget_completion()
        self.command(link, ":STOP")

    def state(self, link: ScpiLink) -> str:
        return self.latched_state(link, ":RSTate?", ":TER?", armed=("SING", "RUN"), stopped="STOP", completed=1)

    def fetch(self, link: ScpiLink, channel: str, context: DigitizerSettings) -> Waveform:
        units = [f":WAVeform:SOURce CHANnel{self.channel_number(channel):d}", ":WAVeform:PREamble?",
                 ":WAVeform:UNSigned?", ":WAVeform:BYTeorder?"]
        command = self.join(*units)
        preamble, unsigned, order = self.query_fields(link, units, count=3)
        reply = self.join(preamble, unsigned, order)
        f = [x.strip() for x in preamble.split(",")]
        if len(f) < 10:
            raise ReplyFormatError(command, f"preamble has {len(f)} fields, expected 10", reply)
        fmt_code, points = self.integer(command, f[0], reply), self.integer(command, f[2], reply)
        x_inc, x_origin, x_ref = (self.number(command, v, reply) for v in f[4:7])
        y_inc, y_origin, y_ref = (self.number(command, v, reply) for v in f[7:10])
        signed = {"0": True, "1": False}.get(unsigned.strip())
        byte_order = {"LSBF": "little", "MSBF": "big"}.get(order.strip().upper()[:4])
        if fmt_code not in (0, 1) or signed is None or byte_order is None:
            raise ReplyFormatError(command, f"unsupported waveform format (format {fmt_code}, unsigned "
                                            f"{unsigned!r}, byte order {order!r}): BYTE or WORD binary only", reply)
        sample_format = ("int" if signed else "uint") + ("8" if fmt_code == 0 else "16")
        dtype = sample_dtype(sample_format, byte_order)
        lowest, highest = integer_rails(dtype)  # lowest: a hole; one above it: clipped low
        return self.fetch_samples(link, ":WAVeform:DATA?", channel, context, preamble=(command, reply), points=points,
                                  dtype=dtype, scale_v=y_inc, offset_v=y_origin - y_ref * y_inc,
                                  sample_interval_s=x_inc, trigger_index=int(round(x_ref - x_origin / x_inc)),
                                  code_range=(lowest + 1, highest))
