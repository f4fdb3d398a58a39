"""The rig's digitizer: a VISA instrument spoken to in its vendor's dialect.

    with Digitizer("TCPIP0::127.0.0.1::5025::SOCKET", dialect="keysight",
                   channels={"doppler": "CHAN1", "response": "CHAN2"}) as dig:
        dig.configure(DigitizerSettings(sample_rate_hz=100e6, record_length=200_000,
                      pre_trigger_samples=20_000, ranges_v={"CHAN1": 1.0, "CHAN2": 10.0},
                      trigger_source="CHAN2", trigger_level_v=0.2, trigger_slope="POS"))
        assert not dig.settings().differences(configured)      # read back: what ARM checks
        dig.arm_single()
        if dig.wait_for_trigger(timeout_s=2.0):
            beat = dig.fetch_waveform("doppler")                 # by role, or "CHAN1"

Layers: `VisaLink` (drivers/digitizer_visa.py) moves bytes (configurable VISA library and
terminations; every read bounded in size and time); the dialect (drivers/scpi_dialect.py and
drivers/digitizer_*.py) knows the words and parses the replies, with the configured settings as
context; this class holds them together, validates requests before anything is sent, maps
roles to channels, and names the instrument in every error. It derives from the one driver base
(drivers/base.py): life cycle, a lock around every transaction, the `trace` hook, and a link
that a failure closed is reopened on the next call.

Channels. `channels` maps the rig's roles (doppler, response, doppler_quadrature, response_2)
to the instrument's channel names. `fetch_waveform` takes a role, a channel name, or a channel
number (1 = the dialect's first channel).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from hopkinson.drivers.base import InstrumentDriver, TraceHook
from hopkinson.drivers.digitizer_settings import DigitizerSettings, pre_trigger_samples
from hopkinson.drivers.digitizer_visa import VisaLink
from hopkinson.drivers.digitizer_waveform import Waveform
from hopkinson.drivers.errors import InstrumentError
from hopkinson.drivers.scpi_dialect import (
    DialectError,
    DigitizerDialect,
    GenericScpiDialect,
    TransferFormat,
    resolve_dialect,
)

__all__ = ["Digitizer", "DigitizerSettings", "Waveform", "make_dialect"]

ROLES = ("doppler", "doppler_quadrature", "response", "response_2")
DEFAULT_MAX_REPLY_BYTES = 65536


def make_dialect(dialect: str | DigitizerDialect | None, sample_format: str = "int16",
                 byte_order: str = "little") -> DigitizerDialect:
    """A dialect instance from a configured name ("generic", "keysight", "tektronix",
    "lecroy", "package.module:Class"), an instance (returned as is) or None (generic)."""
    if isinstance(dialect, DigitizerDialect):
        return dialect
    cls = GenericScpiDialect if dialect is None else resolve_dialect(dialect)
    return cls(TransferFormat(sample_format, byte_order))


class Digitizer(InstrumentDriver):
    """A digitizer reached through VISA (module docstring); use as a context manager.

    resource: VISA resource, e.g. "TCPIP0::192.168.0.20::5025::SOCKET".
    timeout_s: deadline of each reply. name: how errors name the instrument (the resource is
    added). dialect: see make_dialect. channels: role -> channel name. visa_library: "@py"
    (pyvisa-py), a system VISA's path, or "@ivi". read/write_termination: message terminators.
    max_reply_bytes: the longest text reply accepted. sample_format/byte_order: how waveform
    samples are asked for (the dialect says which it can transfer).
    """

    def __init__(
        self,
        resource: str,
        timeout_s: float = 5.0,
        name: str = "digitizer",
        dialect: str | DigitizerDialect | None = None,
        *,
        channels: Mapping[str, str] | None = None,
        visa_library: str = "@py",
        read_termination: str = "\n",
        write_termination: str = "\n",
        max_reply_bytes: int = DEFAULT_MAX_REPLY_BYTES,
        sample_format: str = "int16",
        byte_order: str = "little",
        trace: TraceHook | None = None,
    ) -> None:
        super().__init__(f"{name} ({resource})", timeout_s=timeout_s, trace=trace)
        if not (isinstance(max_reply_bytes, int) and max_reply_bytes >= 64):
            raise ValueError(f"{self.name}: max_reply_bytes must be an integer >= 64, got {max_reply_bytes!r}")
        self.resource = resource
        self.dialect = make_dialect(dialect, sample_format, byte_order)
        self.channels = {role: self.dialect.channel_name(ch) for role, ch in (channels or {}).items()}
        self._context: DigitizerSettings | None = None
        self._link = VisaLink(self.name, resource, library=visa_library, read_termination=read_termination,
                              write_termination=write_termination, timeout_s=self.timeout_s,
                              max_reply_bytes=max_reply_bytes, trace_out=self._trace_out, trace_in=self._trace_in)

    # -- InstrumentDriver ----------------------------------------------------------------------
    def _open(self) -> None:
        self._link.open()
        self._call(self.dialect.identity_query, lambda link: link.query(self.dialect.identity_query))
        self._call("prepare", self.dialect.prepare)

    def _close_link(self) -> None:
        self._link.close()

    def _link_open(self) -> bool:
        return self._link.is_open

    # -- identity and settings -----------------------------------------------------------------
    def identity(self) -> str:
        """The instrument's *IDN? reply (manufacturer,model,serial,firmware)."""
        return self._transaction(self.dialect.identity_query,
                                 lambda link: link.query(self.dialect.identity_query))

    @property
    def context(self) -> DigitizerSettings | None:
        """The settings last sent (the dialect's context), or None."""
        return self._context

    def configure(self, settings: DigitizerSettings | None = None, **changes: Any) -> None:
        """Send acquisition settings: a whole DigitizerSettings, or changes to what the
        instrument holds, by field name (sample_rate_hz, record_length, pre_trigger_samples or
        pre_trigger_fraction, trigger_source/level_v/slope, ranges_v={channel: volts}, or the
        older ch1_range_v, ch2_range_v). Checked before anything is sent."""
        if settings is None:
            settings = self._with_changes(self.settings(), changes)
        elif changes:
            raise TypeError("give a DigitizerSettings or keyword changes, not both")
        settings = self._checked(settings)
        self._transaction("configure", lambda link: self.dialect.apply(link, settings))
        self._context = settings

    def settings(self) -> DigitizerSettings:
        """The acquisition settings read back from the instrument (for the channels of the
        configured settings, or of the role map, or all the dialect's channels)."""
        return self._transaction("read settings", lambda link: self.dialect.read_settings(link, self._read_context()))

    # Older single-setting calls (kept for callers that set one thing at a time).
    def sample_rate_hz(self) -> float:
        return self.settings().sample_rate_hz

    def record_length(self) -> int:
        return self.settings().record_length

    def channel_range_v(self, channel: str | int) -> float:
        """The channel's full scale (±volts), read back."""
        name = self._channel(channel)
        context = self._read_context().with_changes(ranges_v={name: 1.0})
        return self._transaction("read settings", lambda link: self.dialect.read_settings(link, context)).ranges_v[name]

    # -- acquisition ---------------------------------------------------------------------------
    def arm_single(self) -> None:
        """Arm one acquisition (ARMED until the trigger comes)."""
        self._transaction("arm", self.dialect.arm)

    def abort(self) -> None:
        """Stop: disarm (IDLE)."""
        self._transaction("abort", self.dialect.abort)

    def acquisition_state(self) -> str:
        """"IDLE", "ARMED" or "TRIGGERED" (a record is ready to fetch)."""
        return self._transaction("acquisition state", self.dialect.state)

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
                raise InstrumentError(self.instrument, "acquisition state", "waiting for a trigger but the "
                                      "digitizer is not armed", state)
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll_interval_s)

    def fetch_waveform(self, channel: str | int) -> Waveform:
        """The last acquired record of one channel (a role, a channel name or number)."""
        name = self._channel(channel)
        context = self._context or self.settings()  # the record expected (read back when never configured)
        return self._transaction(f"fetch {name}", lambda link: self.dialect.fetch(link, name, context))

    # -- helpers ---------------------------------------------------------------------------------
    def _channel(self, channel: str | int) -> str:
        try:
            if isinstance(channel, int) and not isinstance(channel, bool):
                if not 1 <= channel <= len(self.dialect.channel_names):
                    raise ValueError(f"channel number must be 1..{len(self.dialect.channel_names)}")
                return self.dialect.channel_names[channel - 1]
            if isinstance(channel, str) and channel in self.channels:
                return self.channels[channel]
            if isinstance(channel, str):
                return self.dialect.channel_name(channel)
            raise ValueError("a channel is a role, a channel name or a channel number")
        except ValueError as exc:
            roles = f"; roles: {', '.join(self.channels)}" if self.channels else ""
            raise InstrumentError(self.instrument, f"channel = {channel!r}", f"{exc}{roles}") from None

    def _read_context(self) -> DigitizerSettings:
        """The configured settings, or (never configured) the channels to read back: the role
        map's, else all of the dialect's."""
        if self._context is not None:
            return self._context
        channels = tuple(dict.fromkeys(self.channels.values())) or self.dialect.channel_names
        return DigitizerSettings(sample_rate_hz=1.0, record_length=1, pre_trigger_samples=0,
                                 ranges_v=dict.fromkeys(channels, 1.0), trigger_source=channels[0])

    def _with_changes(self, held: DigitizerSettings, changes: dict[str, Any]) -> DigitizerSettings:
        """The held settings with keyword changes applied (the older names included)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        ranges = dict(changes.pop("ranges_v", {}) or {})
        for number in (1, 2, 3, 4):
            value = changes.pop(f"ch{number}_range_v", None)
            if value is not None:
                ranges[self._channel(number)] = value
        fraction = changes.pop("pre_trigger_fraction", None)
        if fraction is not None:
            if "pre_trigger_samples" in changes:
                raise ValueError(f"{self.name}: give pre_trigger_fraction or pre_trigger_samples, not both")
            if not (isinstance(fraction, int | float) and 0 <= fraction < 1):
                raise InstrumentError(self.instrument, f"pre_trigger_fraction = {fraction!r}",
                                      "pre_trigger_fraction must be in [0, 1)")
            length = changes.get("record_length", held.record_length)
            if isinstance(length, int) and length >= 1:
                changes["pre_trigger_samples"] = pre_trigger_samples(fraction, length)
        if "record_length" in changes and "pre_trigger_samples" not in changes:
            length = changes["record_length"]
            if isinstance(length, int) and held.pre_trigger_samples >= length >= 1:
                changes["pre_trigger_samples"] = length - 1
        unknown = set(changes) - {"sample_rate_hz", "record_length", "pre_trigger_samples", "trigger_source",
                                  "trigger_level_v", "trigger_slope"}
        if unknown:
            raise TypeError(f"{self.name}: unknown digitizer settings: {', '.join(sorted(unknown))}")
        merged = dict(held.ranges_v) | {self._channel(ch): v for ch, v in ranges.items()}
        return held.with_changes(ranges_v=merged, **changes)

    def _checked(self, settings: DigitizerSettings) -> DigitizerSettings:
        """The settings with channel, trigger and slope names in the instrument's spelling
        (roles resolved); raise InstrumentError (nothing sent) when they cannot be sent."""
        problems = []
        try:
            ranges = {self.dialect.channel_name(self.channels.get(ch, ch)): r for ch, r in settings.ranges_v.items()}
            source = self.dialect.trigger_source_name(self.channels.get(settings.trigger_source,
                                                                        settings.trigger_source))
        except ValueError as exc:
            problems.append(str(exc))
            ranges, source = dict(settings.ranges_v), settings.trigger_source
        slope = settings.trigger_slope.strip().upper() if isinstance(settings.trigger_slope, str) else ""
        named = settings.with_changes(ranges_v=ranges, trigger_source=source, trigger_slope=slope)
        problems = named.problems() + problems
        if problems:
            raise InstrumentError(self.instrument, "configure", "; ".join(problems))
        return named.with_changes(sample_rate_hz=float(named.sample_rate_hz),
                                  trigger_level_v=float(named.trigger_level_v))

    def _transaction(self, what: str, job: Any) -> Any:
        """Run one dialect job on the link under the lock (reopening a link a failure closed)."""
        with self.lock:
            self._ensure_link(what)
            return self._call(what, job)

    def _call(self, what: str, job: Any) -> Any:
        try:
            return job(self._link)
        except DialectError as exc:
            raise InstrumentError(self.instrument, exc.command or what, exc.problem, exc.reply) from None

