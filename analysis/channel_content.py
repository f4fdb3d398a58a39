"""Does a recorded channel carry what its role says? A quadrature photodetector's channel must
carry the beat, a sensor's channel the pulse; a channel mapped to a role that holds only noise
(an interferometer with one photodetector, a second sensor not connected) is named as such,
with the fix, instead of failing later as "the reference's pulse is lost in its noise".

The doppler channel says when the object moves: its windowed power (the variance in windows of
~1/400 of the record) rises far above its rest level (the 2nd percentile of the windows) while
the beat runs. A channel judged against it:

- a beat channel (doppler_quadrature): its windowed variance in those same windows, over its
  own rest level. A quadrature photodetector's beat rises as the doppler's does (tens of dB);
  noise stays where it was (~0 dB).
- a sensor channel (response, response_2): its windowed mean square about its rest level
  (the median of its quietest windows), the largest while the object moves (the pulse takes a
  few windows; a separated object flies on at rest), over its rest noise.

`rise_db` below EMPTY_RISE_DB (3 dB), or a constant channel (NaN), carries nothing. When the doppler channel itself shows no
motion (its beat rises less than MOTION_RISE_DB), nothing is judged (None): the reference's own
checks say what is wrong with it. Pure NumPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EMPTY_RISE_DB = 3.0  # a channel whose power rises less than this while the object moves carries nothing
MOTION_RISE_DB = 10.0  # the doppler channel's windows this far above its rest level: the object moves
WINDOWS = 400  # windows per record (at least MIN_WINDOW samples each)
MIN_WINDOW = 32
REST_PERCENTILE = 2.0  # the rest level: the quietest windows (a pre-trigger of 2 % of the record at least)
QUADRATURE, SENSOR = "beat", "pulse"


@dataclass(frozen=True)
class ChannelContent:
    """How much a channel's power rises, in dB over its rest, while the doppler channel's beat
    rises `reference_rise_db` over its own."""

    role: str
    kind: str  # QUADRATURE ("beat") or SENSOR ("pulse")
    rise_db: float
    reference_rise_db: float

    @property
    def carries_nothing(self) -> bool:
        return not self.rise_db >= EMPTY_RISE_DB  # NaN (a flat channel) carries nothing too

    def message(self) -> str:
        """What the channel holds, and what to do about it (only for one that carries nothing)."""
        held = "it is constant: one value throughout" if math.isnan(self.rise_db) else \
            f"holds only noise: its power rises {self.rise_db:.1f} dB while the doppler channel's beat rises " \
            f"{self.reference_rise_db:.0f} dB"
        if self.kind == QUADRATURE:
            return (f"the {self.role} channel carries no beat ({held}): an interferometer with one photodetector "
                    f"has no quadrature channel: unmap the quadrature channel (digitizer.channels.{self.role} in "
                    "the rig configuration) and its shots are analysed from the doppler channel's PM beat alone")
        sensor = "the accelerometer" if self.role == "response" else f"a sensor on {self.role}"
        return (f"the {self.role} channel carries no pulse ({held}): is {sensor} connected and its conditioner "
                f"on? If the rig has no such sensor, unmap the channel (digitizer.channels.{self.role} in the rig "
                "configuration)")


    def fix(self) -> str:
        """The fix alone (for `probe`'s "fix:" line)."""
        if self.kind == QUADRATURE:
            return (f"unmap the quadrature channel: remove digitizer.channels.{self.role} from the rig configuration "
                    "(an interferometer with one photodetector), or connect its second photodetector")
        return (f"connect the sensor and switch its conditioner on, or remove digitizer.channels.{self.role} from "
                "the rig configuration")


def _windows(n: int) -> int:
    return max(MIN_WINDOW, n // WINDOWS)


def _blocks(x: np.ndarray, window: int) -> np.ndarray:
    usable = (x.size // window) * window
    return np.asarray(x[:usable], dtype=float).reshape(-1, window)


def _motion(doppler_v: np.ndarray, window: int) -> tuple[np.ndarray, float] | None:
    """The windows where the doppler channel's beat runs, and its rise in dB; None without motion."""
    power = _blocks(doppler_v, window).var(axis=1)
    rest = float(np.percentile(power, REST_PERCENTILE))
    if rest <= 0:
        rest = float(np.min(power[power > 0])) if np.any(power > 0) else 0.0
    if rest <= 0:
        return None
    moving = power >= rest * 10 ** (MOTION_RISE_DB / 10)
    if np.count_nonzero(moving) < 3:
        return None
    return moving, 10 * math.log10(float(np.median(power[moving])) / rest)


def _rise_db(power: np.ndarray, moving: np.ndarray, during_statistic: str = "median") -> float:
    rest = float(np.percentile(power, REST_PERCENTILE))
    during = float(getattr(np, during_statistic)(power[moving]))
    if rest <= 0:
        return math.inf if during > 0 else math.nan  # noise-free rest: any content is a rise; none: flat
    return 10 * math.log10(max(during, 1e-300) / rest)


def beat_content(quadrature_v: np.ndarray, doppler_v: np.ndarray,
                 role: str = "doppler_quadrature") -> ChannelContent | None:
    """Does the quadrature channel carry the beat (module docstring)? None: the doppler channel
    shows no motion to judge it by."""
    return _content(quadrature_v, doppler_v, role, QUADRATURE)


def pulse_content(response_v: np.ndarray, doppler_v: np.ndarray, role: str = "response") -> ChannelContent | None:
    """Does the sensor channel carry the pulse (module docstring)? None: no motion to judge by."""
    return _content(response_v, doppler_v, role, SENSOR)


def _content(x: np.ndarray, doppler_v: np.ndarray, role: str, kind: str) -> ChannelContent | None:
    doppler_v = np.asarray(doppler_v)
    window = _windows(doppler_v.size)
    motion = _motion(doppler_v, window)
    if motion is None:
        return None
    moving, reference_db = motion
    if np.ptp(x) == 0:
        return ChannelContent(role, kind, math.nan, reference_db)  # constant
    blocks = _blocks(np.asarray(x), window)[: moving.size]
    if kind == QUADRATURE:
        return ChannelContent(role, kind, _rise_db(blocks.var(axis=1), moving), reference_db)
    noise = blocks.var(axis=1)
    quiet = noise <= np.percentile(noise, REST_PERCENTILE)
    level = float(np.median(blocks.mean(axis=1)[quiet]))  # the rest level: offsets and drift-free windows
    power = ((blocks - level) ** 2).mean(axis=1)
    # the largest: the pulse takes a few windows; a separated object flies on (the beat runs) at rest
    return ChannelContent(role, kind, _rise_db(power, moving, "max"), reference_db)
