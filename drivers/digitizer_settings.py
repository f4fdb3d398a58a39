"""The digitizer's acquisition settings, as configured and as read back from the instrument.

One `DigitizerSettings` describes what the rig configuration asks for (rig.config builds it
from [digitizer]) and what the instrument holds (`Digitizer.settings()` reads it back). The
sequencer compares the two in ARM, immediately before FIRE: `configured.differences(held)` is
empty when the instrument records what the shot needs. Each dialect also gets the configured
settings as context (which channels, record length, trigger), e.g. to turn a pre-trigger
percentage into samples.

Channel names are the instrument's own ("CH1" generic/Tektronix, "CHAN1" Keysight, "C1"
LeCroy); the rig maps roles to them in [digitizer.channels].
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

TRIGGER_SLOPES = ("POS", "NEG")

# Read-back tolerances: instruments round what they are sent (a sample rate to the nearest
# available one, a level to the DAC's step); within these, a read-back value is "the same".
REL_TOL = 1e-6
LEVEL_ABS_TOL_V = 1e-6


@dataclass(frozen=True)
class DigitizerSettings:
    """Acquisition settings of the channels the rig records.

    ranges_v: instrument channel name -> full scale (the channel reads -range .. +range volts).
    trigger_source: a channel name or the dialect's external input; trigger_slope "POS"/"NEG".
    pre_trigger_samples: samples kept before the trigger (below record_length).
    """

    sample_rate_hz: float
    record_length: int
    pre_trigger_samples: int
    ranges_v: Mapping[str, float] = field(default_factory=dict)
    trigger_source: str = "CH1"
    trigger_level_v: float = 0.0
    trigger_slope: str = "POS"
    # Read back only: each recorded channel's on/off state (a scope acquires only the channels
    # that are on); None where the dialect has no such notion or it was not read.
    channels_on: Mapping[str, bool] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "ranges_v", dict(self.ranges_v))
        if self.channels_on is not None:
            object.__setattr__(self, "channels_on", dict(self.channels_on))

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(self.ranges_v)

    @property
    def pre_trigger_fraction(self) -> float:
        return self.pre_trigger_samples / self.record_length

    def problems(self) -> list[str]:
        """What is wrong with these settings as a request (empty when they can be sent)."""
        out = []
        if not _positive(self.sample_rate_hz):
            out.append(f"sample_rate_hz must be a positive number, got {self.sample_rate_hz!r}")
        if not _count(self.record_length, 1):
            out.append(f"record_length must be an integer >= 1, got {self.record_length!r}")
        if not _count(self.pre_trigger_samples, 0) or (
                _count(self.record_length, 1) and self.pre_trigger_samples >= self.record_length):
            out.append(f"pre_trigger_samples must be an integer in 0 .. record_length - 1, got "
                       f"{self.pre_trigger_samples!r}")
        for channel, range_v in self.ranges_v.items():
            if not _positive(range_v):
                out.append(f"range of {channel} must be a positive number of volts, got {range_v!r}")
        if not (isinstance(self.trigger_level_v, int | float) and not isinstance(self.trigger_level_v, bool)
                and math.isfinite(self.trigger_level_v)):
            out.append(f"trigger_level_v must be a finite number of volts, got {self.trigger_level_v!r}")
        if self.trigger_slope not in TRIGGER_SLOPES:
            out.append(f"trigger_slope must be POS or NEG, got {self.trigger_slope!r}")
        return out

    def differences(self, other: DigitizerSettings) -> list[str]:
        """Every setting in which `other` differs from these (beyond the instrument's rounding),
        one line each: "sample_rate_hz: 100000000 configured, 50000000 on the instrument"."""
        out: list[str] = []

        def differ(name: str, mine: object, theirs: object) -> None:
            out.append(f"{name}: {_text(mine)} configured, {_text(theirs)} on the instrument")

        if not _close(self.sample_rate_hz, other.sample_rate_hz):
            differ("sample_rate_hz", self.sample_rate_hz, other.sample_rate_hz)
        if self.record_length != other.record_length:
            differ("record_length", self.record_length, other.record_length)
        slack = max(1, int(self.record_length * 1e-4))  # a percentage rounded by the instrument
        if abs(self.pre_trigger_samples - other.pre_trigger_samples) > slack:
            differ("pre_trigger_samples", self.pre_trigger_samples, other.pre_trigger_samples)
        for channel, range_v in self.ranges_v.items():
            held = other.ranges_v.get(channel)
            if held is None or not _close(range_v, held):
                differ(f"range of {channel} (V)", range_v, held)
        if self.trigger_source != other.trigger_source:
            differ("trigger_source", self.trigger_source, other.trigger_source)
        if not math.isclose(self.trigger_level_v, other.trigger_level_v, rel_tol=REL_TOL, abs_tol=LEVEL_ABS_TOL_V):
            differ("trigger_level_v", self.trigger_level_v, other.trigger_level_v)
        if self.trigger_slope != other.trigger_slope:
            differ("trigger_slope", self.trigger_slope, other.trigger_slope)
        for channel, on in (other.channels_on or {}).items():
            if not on:
                out.append(f"{channel}: off on the instrument (the rig records it: it must be on, or nothing "
                           "is acquired on it)")
        return out

    def with_changes(self, **changes: object) -> DigitizerSettings:
        """A copy with some fields replaced."""
        return replace(self, **changes)  # type: ignore[arg-type]

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form (stored with each shot)."""
        return {
            "sample_rate_hz": self.sample_rate_hz,
            "record_length": self.record_length,
            "pre_trigger_samples": self.pre_trigger_samples,
            "ranges_v": dict(self.ranges_v),
            "trigger_source": self.trigger_source,
            "trigger_level_v": self.trigger_level_v,
            "trigger_slope": self.trigger_slope,
        } | ({} if self.channels_on is None else {"channels_on": dict(self.channels_on)})


def pre_trigger_samples(fraction: float, record_length: int) -> int:
    """Samples before the trigger for a fraction of the record (0.1 of 200 000 -> 20 000)."""
    return min(int(round(fraction * record_length)), record_length - 1)


def _positive(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value > 0


def _count(value: object, minimum: int) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= minimum


def _close(a: float, b: float | None) -> bool:
    return b is not None and math.isclose(a, b, rel_tol=REL_TOL)


def _text(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)
