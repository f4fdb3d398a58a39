"""Clipping judged against the digitizer's full scale (the volts of its lowest and highest
codes), never against the record itself."""

from __future__ import annotations

import math

import numpy as np

from hopkinson.analysis.errors import AnalysisError

# The volts of a channel's lowest and highest digitizer codes (its full scale).
FullScale = tuple[float, float]
# A sample within this fraction of the span from a full-scale end sits on it (volts rebuilt
# from codes, possibly through float32: far below half a code step of any format ≤ 19 bits).
_FULL_SCALE_TOLERANCE = 1e-6


def full_scale_volts(code_range: tuple[float, float], scale_v: float, offset_v: float) -> FullScale:
    """The full scale in volts of a channel stored as codes (the shot file's /raw/<role>
    attributes code_min, code_max, scale_v, offset_v: volts = codes · scale_v + offset_v)."""
    ends = sorted((code_range[0] * scale_v + offset_v, code_range[1] * scale_v + offset_v))
    return float(ends[0]), float(ends[1])


def samples_at_full_scale(x: np.ndarray, full_scale_v: FullScale) -> int:
    """How many samples of `x` (volts) reach the digitizer's full scale (either end or beyond)."""
    lo, hi = full_scale_v
    tol = _FULL_SCALE_TOLERANCE * abs(hi - lo)
    v = np.asarray(x, dtype=float)
    return int(np.count_nonzero((v <= lo + tol) | (v >= hi - tol)))


def check_not_clipped(x: np.ndarray, full_scale_v: FullScale | None, what: str, remedy: str) -> None:
    """Raise AnalysisError naming `what` when samples of `x` sit at the digitizer's full scale.

    Clipping is judged against the instrument, never against the record itself: a quantised
    record whose extreme code repeats (a wide pulse, a slow digitizer) is not clipped. Without
    `full_scale_v` (a table file, an old shot file) nothing is judged here: the rig judged the
    shot when it was recorded (rig.shot.clipping_problems); `identify` warns of a table file's
    flat top (`flat_top_warnings`)."""
    if full_scale_v is None:
        return
    lo, hi = full_scale_v
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise AnalysisError(f"{what}: the digitizer's full scale must be two finite volts, low < high; got {full_scale_v!r}")
    count = samples_at_full_scale(x, full_scale_v)
    if count:
        raise AnalysisError(f"{what}: clipped: {count} samples at the digitizer's full scale ({lo:.4g} .. {hi:.4g} V): "
                            f"{remedy}")
