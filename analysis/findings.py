"""What a stage of the analysis found that the reader must know: a typed code and its text.

The results list the texts in the order the stages found them (`texts`); code reads the codes.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum


class FindingCode(StrEnum):
    """What a finding is about, one code per kind of warning."""

    # prepare: the record, its noise and its band (analysis.record_preparation)
    NOT_AT_REST = "not_at_rest"  # a channel moves after the pulse and has no lead-in to measure its noise
    NO_QUIET_REFERENCE = "no_quiet_reference"
    NO_QUIET_RESPONSE = "no_quiet_response"
    CUT_SHORT = "cut_short"  # the record ends before the response died away: a transient term
    # search the orders (analysis.order_search)
    ORDERS_CAPPED = "orders_capped"  # the band's bins allow fewer orders than asked
    ORDER_UNSTABLE = "order_unstable"  # the order choice is not stable under the record's noise
    ASKED_ORDER_UNSUPPORTED = "asked_order_unsupported"
    ALL_POLE_FALLBACK = "all_pole_fallback"
    UNSTABLE_WHEN_CONVERGED = "unstable_when_converged"
    NOT_CONVERGED = "not_converged"
    BAND_CUT = "band_cut"  # the band stops past the pulse's first null
    # the model error and the residual (analysis.identify)
    MODEL_ERROR = "model_error"
    MOTION_LEFT_OUT = "motion_left_out"
    RESIDUAL_BEYOND_NOISE = "residual_beyond_noise"
    POOR_FIT = "poor_fit"
    # claim: modes and delay (analysis.claims)
    DOUBLET = "doublet"
    SHAPES_BAND = "shapes_band"
    NO_RESONANCE = "no_resonance"  # a supported pair damped beyond a resonance
    MODE_OUTSIDE_BAND = "mode_outside_band"
    NO_MODE_IN_BAND = "no_mode_in_band"
    REALIGNED = "realigned"  # the response led and was realigned before the fit
    NEGATIVE_DELAY = "negative_delay"
    RESPONSE_LEADS = "response_leads"
    SKEW_NOT_TAKEN = "skew_not_taken"  # a lead at the edge of the search, not realigned
    # the joint fit with a sine calibration (analysis.sine_joint)
    SINE_REWEIGHING_FAILED = "sine_reweighing_failed"
    # the uncertainty (analysis.uncertainty)
    DRAWS_FAILED = "draws_failed"
    UNCERTAINTY_OFF = "uncertainty_off"
    UNCERTAINTY_FAILED = "uncertainty_failed"


@dataclass(frozen=True)
class Finding:
    """One warning: its code and the text the results and the reader see."""

    code: FindingCode
    text: str


def texts(findings: Iterable[Finding]) -> list[str]:
    """The findings' texts, in order (what the JSON's `warnings` lists)."""
    return [f.text for f in findings]
