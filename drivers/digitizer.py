"""Two-channel digitizer driver: SCPI over VISA (pyvisa + pyvisa-py, raw TCP socket).

    with Digitizer("TCPIP0::127.0.0.1::5025::SOCKET", timeout_s=5.0) as dig:
        dig.configure(sample_rate_hz=100e6, record_length=1_000_000, pre_trigger_fraction=0.1,
                      ch1_range_v=1.0, ch2_range_v=10.0, trigger_source="CH2",
                      trigger_level_v=0.1, trigger_slope="POS")
        dig.arm_single()
        if dig.wait_for_trigger(timeout_s=2.0):
            beat = dig.fetch_waveform(1).volts()

Every setting is sent together with the instrument's error query in one message, so a refused
command is reported at once, naming the instrument, the command and the reply. Any I/O
failure (timeout, dropped link, garbled block) closes the session, because the byte stream is
no longer in step; `connect()` (or a new `with` block) opens a fresh one.

Waveform blocks are read by length with the termination character switched off: pyvisa's
default `query_binary_values` leaves it on, so every 0x0A byte in the int16 payload ends one
low-level read (~15-30 MB/s); by length, the transfer runs near raw-socket speed.
"""

from __future__ import annotations

import math
import time
from dataclasses import astuple, dataclass

import numpy as np
import pyvisa
import pyvisa.constants
import pyvisa.errors
from hopkinson.drivers.errors import InstrumentConnectionError, InstrumentError, InstrumentTimeout
from hopkinson.drivers.ieee488_block import BlockFormatError, read_block
from hopkinson.drivers.scpi_dialect import GenericScpiDialect, Preamble, ReplyFormatError

# Size of each low-level read of a waveform block (each read has its own timeout), and the
# receive size given to pyvisa-py's socket session (see _enlarge_receive_size). Measured on
# loopback, 10 M samples: 4 KiB receives ~450-650 MB/s; 64 KiB ~1300 MB/s; 1 MiB ~1550-1650 MB/s.
BLOCK_CHUNK_BYTES = 1 << 20


def _enlarge_receive_size(inst: pyvisa.resources.MessageBasedResource) -> None:
    """Let pyvisa-py's TCPIP SOCKET session receive up to BLOCK_CHUNK_BYTES per recv() call.

    pyvisa-py (0.7-0.8) fixes `max_recv_size = 4096` in its socket session, with no VISA
    attribute to change it, so a 20 MB block costs ~5000 select()+recv() rounds (the read is
    then ~4x slower than a raw socket). The attribute is set only where the backend session
    has it; with another backend or a future pyvisa-py without it, reads stay correct, only
    slower. recv() returns what is available, so text replies are unaffected.
    """
    sessions = getattr(inst.visalib, "sessions", None)
    session = sessions.get(inst.session) if isinstance(sessions, dict) else None
    if session is not None and isinstance(getattr(session, "max_recv_size", None), int):
        session.max_recv_size = max(session.max_recv_size, BLOCK_CHUNK_BYTES)


@dataclass(frozen=True)
class Waveform:
    """One channel's record as the digitizer sent it.

    codes: int16 samples (read-only view of the received bytes); volts = codes * scale_v +
    offset_v. trigger_index: the sample at which the trigger occurred (t = 0).
    """

    channel: int
    codes: np.ndarray
    scale_v: float
    offset_v: float
    sample_interval_s: float
    trigger_index: int

    @property
    def sample_rate_hz(self) -> float:
        return 1.0 / self.sample_interval_s

    def volts(self) -> np.ndarray:
        """The samples in volts (float64)."""
        return self.codes * self.scale_v + self.offset_v

    def time_s(self) -> np.ndarray:
        """Sample times in seconds, 0 at the trigger."""
        return (np.arange(self.codes.size) - self.trigger_index) * self.sample_interval_s


@dataclass(frozen=True)
class TriggerSettings:
    """Trigger source ("CH1"/"CH2"/"EXT"), level (V), slope ("POS"/"NEG"), pre-trigger samples."""

    source: str
    level_v: float
    slope: str
    pre_trigger_samples: int


class Digitizer:
    """A SCPI digitizer reached through VISA; use as a context manager (connects, always closes).

    resource: VISA resource, e.g. "TCPIP0::192.168.0.20::5025::SOCKET".
    timeout_s: per-operation I/O timeout. name: how errors name the instrument.
    dialect: the vendor's SCPI dialect (drivers/scpi_dialect.py).
    Not thread-safe: one thread drives one instance.
    """

    def __init__(
        self,
        resource: str,
        timeout_s: float = 5.0,
        name: str = "digitizer",
        dialect: GenericScpiDialect | None = None,
    ) -> None:
        if not (isinstance(timeout_s, int | float) and math.isfinite(timeout_s) and timeout_s > 0):
            raise ValueError(f"{name}: timeout_s must be a positive number of seconds, got {timeout_s!r}")
        self.resource = resource
        self.timeout_s = float(timeout_s)
        self.name = name
        self.dialect = dialect or GenericScpiDialect()
        self._rm: pyvisa.ResourceManager | None = None
        self._inst: pyvisa.resources.MessageBasedResource | None = None

    @property
    def instrument(self) -> str:
        """How errors name this instrument: "<name> (<resource>)"."""
        return f"{self.name} ({self.resource})"

    @property
    def connected(self) -> bool:
        return self._inst is not None

    # -- connection ----------------------------------------------------------------------
    def connect(self) -> None:
        """Open the VISA session (closing any old one), check it answers *IDN?, clear errors."""
        self.close()
        try:
            self._rm = pyvisa.ResourceManager("@py")
            inst = self._rm.open_resource(
                self.resource,
                open_timeout=int(self.timeout_s * 1000),
                timeout=int(self.timeout_s * 1000),
                read_termination="\n",
                write_termination="\n",
            )
        except Exception as exc:  # pyvisa-py raises bare Exception for a bad address/refusal
            self.close()
            raise InstrumentConnectionError(self.instrument, "open", f"cannot open the VISA session: {exc}") from exc
        self._inst = inst  # type: ignore[assignment]
        _enlarge_receive_size(inst)  # type: ignore[arg-type]
        try:
            self._query(self.dialect.identity_query)  # the session answers
            self._write(self.dialect.clear_status)
        except InstrumentError:
            self.close()
            raise

    def close(self) -> None:
        """Close the session (idempotent; never raises)."""
        inst, rm = self._inst, self._rm
        self._inst, self._rm = None, None
        for thing in (inst, rm):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # closing a broken session must not hide the first error
                    pass

    def __enter__(self) -> Digitizer:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- identity and settings -----------------------------------------------------------
    def identity(self) -> str:
        """The instrument's *IDN? reply (manufacturer,model,serial,firmware)."""
        return self._query(self.dialect.identity_query)

    def set_sample_rate_hz(self, sample_rate_hz: float) -> None:
        self._require_positive("sample_rate_hz", sample_rate_hz)
        self._command(self.dialect.set_sample_rate(float(sample_rate_hz)))

    def sample_rate_hz(self) -> float:
        return self._query_float(self.dialect.sample_rate_query)

    def set_record_length(self, samples: int) -> None:
        """Samples per channel per acquisition."""
        self._require_count("record_length", samples, 1)
        self._command(self.dialect.set_record_length(int(samples)))

    def record_length(self) -> int:
        return self._query_int(self.dialect.record_length_query)

    def set_channel_range_v(self, channel: int, full_scale_v: float) -> None:
        """Vertical range: the channel reads -full_scale_v .. +full_scale_v."""
        self._require_channel(channel)
        self._require_positive(f"ch{channel}_range_v", full_scale_v)
        self._command(self.dialect.set_channel_range(channel, float(full_scale_v)))

    def channel_range_v(self, channel: int) -> float:
        self._require_channel(channel)
        return self._query_float(self.dialect.channel_range_query(channel))

    def set_trigger(self, source: str, level_v: float, slope: str, pre_trigger_samples: int) -> None:
        """Trigger source ("CH1"/"CH2"/"EXT"), level in volts, slope ("POS"/"NEG") and the
        number of samples kept before the trigger (below the record length)."""
        d = self.dialect
        src = self._require_choice("trigger_source", source, d.trigger_sources)
        slp = self._require_choice("trigger_slope", slope, d.trigger_slopes)
        if not (isinstance(level_v, int | float) and not isinstance(level_v, bool) and math.isfinite(level_v)):
            raise InstrumentError(self.instrument, f"trigger_level_v = {level_v!r}", "trigger_level_v must be a finite number of volts")
        self._require_count("pre_trigger_samples", pre_trigger_samples, 0)
        self._command(
            d.set_trigger_source(src),
            d.set_trigger_level(float(level_v)),
            d.set_trigger_slope(slp),
            d.set_pre_trigger(int(pre_trigger_samples)),
        )

    def trigger_settings(self) -> TriggerSettings:
        """The trigger settings as the instrument holds them (one round trip)."""
        d = self.dialect
        command = d.join(d.trigger_source_query, d.trigger_level_query, d.trigger_slope_query, d.pre_trigger_query)
        reply = self._query(command)
        parts = reply.split(d.unit_separator)
        try:
            source, level, slope, pre = parts
            return TriggerSettings(source.strip().upper(), float(level), slope.strip().upper(), int(pre))
        except ValueError:
            raise InstrumentError(self.instrument, command, "unexpected reply to the trigger queries", reply) from None

    def configure(
        self,
        *,
        sample_rate_hz: float | None = None,
        record_length: int | None = None,
        pre_trigger_fraction: float | None = None,
        pre_trigger_samples: int | None = None,
        ch1_range_v: float | None = None,
        ch2_range_v: float | None = None,
        trigger_source: str | None = None,
        trigger_level_v: float | None = None,
        trigger_slope: str | None = None,
    ) -> None:
        """Apply the given settings (the names of the rig's digitizer config); None = keep.

        pre_trigger_fraction (0..1 of the record length) is converted to samples; give it or
        pre_trigger_samples, not both. Trigger fields left out keep the instrument's values.
        """
        if pre_trigger_fraction is not None and pre_trigger_samples is not None:
            raise ValueError(f"{self.name}: give pre_trigger_fraction or pre_trigger_samples, not both")
        if sample_rate_hz is not None:
            self.set_sample_rate_hz(sample_rate_hz)
        if record_length is not None:
            self.set_record_length(record_length)
        for channel, range_v in ((1, ch1_range_v), (2, ch2_range_v)):
            if range_v is not None:
                self.set_channel_range_v(channel, range_v)
        if pre_trigger_fraction is not None:
            if not (isinstance(pre_trigger_fraction, int | float) and 0 <= pre_trigger_fraction < 1):
                raise InstrumentError(
                    self.instrument,
                    self.dialect.pre_trigger_query,
                    f"pre_trigger_fraction must be in [0, 1), got {pre_trigger_fraction!r}",
                )
            length = record_length if record_length is not None else self.record_length()
            pre_trigger_samples = min(int(round(pre_trigger_fraction * length)), length - 1)
        trigger = (trigger_source, trigger_level_v, trigger_slope, pre_trigger_samples)  # set_trigger's order
        if any(v is not None for v in trigger):
            if any(v is None for v in trigger):  # fill the gaps from the instrument (same field order)
                held = astuple(self.trigger_settings())
                trigger = tuple(h if v is None else v for v, h in zip(trigger, held, strict=True))
            self.set_trigger(*trigger)

    # -- acquisition ---------------------------------------------------------------------
    def arm_single(self) -> None:
        """Arm one acquisition (state ARMED until the trigger comes)."""
        self._command(self.dialect.arm_single)

    def abort(self) -> None:
        """Disarm (state IDLE)."""
        self._command(self.dialect.abort)

    def acquisition_state(self) -> str:
        """"IDLE", "ARMED" or "TRIGGERED" (a record is ready to fetch)."""
        reply = self._query(self.dialect.state_query)
        try:
            return self.dialect.parse_state(reply)
        except ReplyFormatError as exc:
            raise InstrumentError(self.instrument, self.dialect.state_query, str(exc), reply) from None

    def wait_for_trigger(self, timeout_s: float, poll_interval_s: float = 0.005) -> bool:
        """Poll the state until TRIGGERED (True) or timeout_s passes (False).

        Raises InstrumentError if the instrument is IDLE (not armed: nothing will come).
        """
        deadline = time.monotonic() + timeout_s
        while True:
            state = self.acquisition_state()
            if state == "TRIGGERED":
                return True
            if state == "IDLE":
                raise InstrumentError(self.instrument, self.dialect.state_query, "waiting for a trigger but the digitizer is not armed", state)
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll_interval_s)

    def fetch_waveform(self, channel: int) -> Waveform:
        """The last acquired record of one channel (int16 codes with their scaling)."""
        self._require_channel(channel)
        d = self.dialect
        command = d.join(d.select_waveform(channel), d.preamble_query)
        reply = self._query(command)
        try:
            preamble = d.parse_preamble(reply)
        except ReplyFormatError as exc:
            raise InstrumentError(self.instrument, command, str(exc), reply) from None
        if preamble.points == 0:
            raise InstrumentError(self.instrument, command, f"no acquired record on channel {channel}", reply)
        payload = self._query_block(d.data_query)
        expected = preamble.points * preamble.dtype.itemsize
        if len(payload) != expected:
            raise InstrumentError(
                self.instrument,
                d.data_query,
                f"block has {len(payload)} bytes, the preamble announced {preamble.points} int16 samples ({expected} bytes)",
            )
        return self._waveform(channel, preamble, payload)

    @staticmethod
    def _waveform(channel: int, preamble: Preamble, payload: memoryview) -> Waveform:
        codes = np.frombuffer(payload, dtype=preamble.dtype)
        if codes.dtype.byteorder == ">":  # native order for arithmetic
            codes = codes.astype(np.int16)
        return Waveform(
            channel=channel,
            codes=codes,
            scale_v=preamble.scale_v,
            offset_v=preamble.offset_v,
            sample_interval_s=preamble.sample_interval_s,
            trigger_index=preamble.trigger_index,
        )

    # -- transport -----------------------------------------------------------------------
    def _session(self, command: str) -> pyvisa.resources.MessageBasedResource:
        if self._inst is None:
            raise InstrumentConnectionError(self.instrument, command, "not connected (call connect() or use 'with')")
        return self._inst

    def _io_failed(self, command: str, exc: Exception, reply: bytes | str = "") -> InstrumentError:
        """Map a transport failure to an InstrumentError and close the (out-of-step) session."""
        self.close()
        if isinstance(exc, pyvisa.errors.VisaIOError) and exc.error_code == pyvisa.constants.StatusCode.error_timeout:
            return InstrumentTimeout(
                self.instrument, command, f"no complete reply within {self.timeout_s:g} s (or the connection dropped)", reply
            )
        if isinstance(exc, BlockFormatError):
            return InstrumentError(self.instrument, command, f"garbled binary block: {exc}", reply)
        if isinstance(exc, UnicodeDecodeError):
            return InstrumentError(self.instrument, command, "garbled reply: not ASCII text", reply)
        return InstrumentConnectionError(self.instrument, command, f"connection failed: {exc}", reply)

    def _write(self, command: str) -> None:
        inst = self._session(command)
        try:
            inst.write(command)
        except (pyvisa.errors.VisaIOError, OSError) as exc:
            raise self._io_failed(command, exc) from exc

    def _query(self, command: str) -> str:
        inst = self._session(command)
        try:
            return inst.query(command).strip()
        except (pyvisa.errors.VisaIOError, OSError) as exc:
            raise self._io_failed(command, exc) from exc
        except UnicodeDecodeError as exc:
            raise self._io_failed(command, exc, exc.object) from exc

    def _query_float(self, command: str) -> float:
        reply = self._query(command)
        try:
            return float(reply)
        except ValueError:
            raise InstrumentError(self.instrument, command, "expected a number", reply) from None

    def _query_int(self, command: str) -> int:
        reply = self._query(command)
        try:
            return int(reply)
        except ValueError:
            raise InstrumentError(self.instrument, command, "expected an integer", reply) from None

    def _command(self, *units: str) -> None:
        """Send setting commands with the error query in one message; raise if refused."""
        d = self.dialect
        command = d.join(*units)
        reply = self._query(d.join(d.clear_status, command, d.error_query))
        try:
            code, message = d.parse_error(reply)
        except ReplyFormatError as exc:
            raise InstrumentError(self.instrument, command, str(exc), reply) from None
        if code != 0:
            raise InstrumentError(self.instrument, command, f"refused by the instrument (error {code}: {message})", reply)

    def _query_block(self, command: str) -> memoryview:
        """Send a query whose reply is one IEEE 488.2 block; read it by length, termchar off."""
        inst = self._session(command)
        term = inst.read_termination

        def read_exact(count: int) -> bytes:
            return inst.read_bytes(count, chunk_size=BLOCK_CHUNK_BYTES)

        try:
            inst.write(command)
            inst.read_termination = None  # 0x0A in the payload must not end a read
            try:
                return read_block(read_exact, terminator=term.encode("ascii"))
            finally:
                if self._inst is inst:
                    inst.read_termination = term
        except (pyvisa.errors.VisaIOError, OSError, BlockFormatError) as exc:
            raise self._io_failed(command, exc) from exc

    # -- validation (before anything is sent) ----------------------------------------------
    def _require_positive(self, what: str, value: object) -> None:
        if not (isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
            raise InstrumentError(self.instrument, f"{what} = {value!r}", f"{what} must be a positive finite number")

    def _require_count(self, what: str, value: object, minimum: int) -> None:
        if not (isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= minimum):
            raise InstrumentError(self.instrument, f"{what} = {value!r}", f"{what} must be an integer >= {minimum}")

    def _require_channel(self, channel: object) -> None:
        if channel not in self.dialect.channels or isinstance(channel, bool):
            raise InstrumentError(self.instrument, f"channel = {channel!r}", f"channel must be one of {self.dialect.channels}")

    def _require_choice(self, what: str, value: object, choices: tuple[str, ...]) -> str:
        text = value.strip().upper() if isinstance(value, str) else ""
        if text not in choices:
            raise InstrumentError(self.instrument, f"{what} = {value!r}", f"{what} must be one of {', '.join(choices)}")
        return text
