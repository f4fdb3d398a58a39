"""What the preparation did to a record before the fit: `Preprocessing`, the results'
`identification.preprocessing` (`to_dict()` writes it as the results JSON holds it)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hopkinson.analysis.identify_stages import BandCut


@dataclass(frozen=True)
class DriftLine:
    """A straight line taken off a channel, in its units: intercept + slope_per_s·(t − origin_s)
    (t in s on the record's clock), on top of the channel's baseline."""

    intercept: float
    slope_per_s: float  # channel units per s
    origin_s: float

    def to_dict(self) -> dict[str, Any]:
        return {"intercept": self.intercept, "slope_per_s": self.slope_per_s, "origin_s": self.origin_s}


@dataclass(frozen=True)
class Preprocessing:
    """How a record was prepared for the fit (channel units unless named; None: not done)."""

    record_sample_rate_hz: float
    reference_baseline: float  # the baseline taken off the reference
    response_baseline: float
    drift_removed: bool
    reference_drift: DriftLine
    response_drift: DriftLine
    window_start_s: float  # the fitted window's start, s on the record's clock
    window_samples: int
    fitted_bins: int
    bin_group: int  # DFT bins grouped into one fitted bin
    transient_term: bool  # a transient term fitted (the record ends before the response settles)
    scale_reference: float  # the reference = scale_reference × its normalised samples
    scale_response: float
    resampled_to_hz: float | None = None  # the analysis rate, when the record was resampled to it
    response_lead_by_cross_correlation_samples: float | None = None  # None: no lead found
    response_realigned_samples: int | None = None  # the response delayed by these samples before the fit
    response_offset_fitted: float | None = None  # the final fit's mean residual (set by identify)
    band_cut: BandCut | None = None  # where identify cut the band (None: not cut)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, the optional entries only when done, in the results' order."""
        out: dict[str, Any] = {"record_sample_rate_hz": self.record_sample_rate_hz}
        for name in ("resampled_to_hz", "response_lead_by_cross_correlation_samples", "response_realigned_samples"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        out.update({
            "reference_baseline": self.reference_baseline,
            "response_baseline": self.response_baseline,
            "baseline_removed": True,
            "drift_removed": self.drift_removed,
            "reference_drift": self.reference_drift.to_dict(),
            "response_drift": self.response_drift.to_dict(),
            "window_start_s": self.window_start_s,
            "window_samples": self.window_samples,
            "fitted_bins": self.fitted_bins,
            "bin_group": self.bin_group,
            "transient_term": self.transient_term,
            "scale_reference": self.scale_reference,
            "scale_response": self.scale_response,
        })
        if self.response_offset_fitted is not None:
            out["response_offset_fitted"] = self.response_offset_fitted
        if self.band_cut is not None:
            out["band_cut"] = self.band_cut.to_dict()
        return out
