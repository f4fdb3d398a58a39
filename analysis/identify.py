"""Identify the accelerometer's discrete model A(d⁻¹)·y(k) = B(d⁻¹)·u(k − delay) from a shock record.

Steps (paper §2.1, done as PAPER-NOTES.md measured it must be done):

1. Rate: a record sampled faster than the analysis rate is low-pass filtered and resampled
   (analysis.resample; default 1 MS/s).
2. Baselines: each channel's mean before the pulse is removed; what is left of a response
   offset is fitted with every model (a constant output term).
3. Bias correction per order 1 … N by refined instrumental variables with prefiltering by 1/Â
   (Eq. 12; analysis.refined_iv), started from plain least squares. The integer input delay
   is estimated and removed per order, alternating the fit with the delay that minimises the
   output error for the fitted denominator (scored for every shift at once); B keeps b_0, so
   a fractional remainder is absorbed by the model.
4. Order: chosen on the bias-corrected output-error loss Σ(y − c − (B/A)u)² — the smallest
   order within a tolerance of the best (the knee). The plain least-squares loss ||g2||² of
   every order (one factorisation of the augmented information matrix of Eq. 3,
   analysis.loss) keeps falling and would always pick N; it is reported beside AIC and BIC.
5. The chosen order is iterated to convergence (and polished by a direct output-error fit if
   SRIV will not settle); an unstable or non-converging result is an error when the order was
   asked for, and is never returned silently otherwise (fallback order + warning).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.excitation import supported_band_hz
from hopkinson.analysis.loss import arx_coefficients_by_order, arx_loss_by_order, long_dot
from hopkinson.analysis.model import DiscreteModel, complex_pairs
from hopkinson.analysis.records import Record
from hopkinson.analysis.refined_iv import (
    TransferFit,
    output_error_refine,
    refined_iv_fit,
    simulate,
    stabilised,
)
from hopkinson.analysis.resample import (
    DEFAULT_ANALYSIS_RATE_HZ,
    estimate_delay_samples,
    resample_to_rate,
)
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft, linalg, signal

# Samples per model parameter below which a record is too short for an order.
MIN_SAMPLES_PER_PARAMETER = 10
# An identified mode whose band the reference hardly excites (input amplitude spectrum around
# its natural frequency below this fraction of the spectrum's peak) is not supported by the data.
EXCITATION_FLOOR = 1e-2
# A final model with a pole this close to the unit circle (a time constant beyond 10⁶ samples,
# seconds at the analysis rate) sits on the stability boundary: the fit pushed against it, so
# the data call for an unstable model. It is treated as unstable.
MARGINAL_POLE = 1e-6
# Below this fit percentage the model is reported as explaining little of the response.
POOR_FIT_PERCENT = 50.0


@dataclass
class Identification:
    """The identified model and everything that went into choosing it.

    Losses are sums of squared errors in response units² over the aligned record; index 0 of
    every *_by_order list is order 1; a loss is inf where that order's fit failed (unstable).
    """

    model: DiscreteModel
    order: int
    loss_by_order: list[float]  # bias-corrected output-error loss (the order choice uses it)
    arx_loss_by_order: list[float]  # plain least-squares ||g2||², one factorisation
    aic_by_order: list[float]  # on the bias-corrected loss
    bic_by_order: list[float]
    fit_percent: float  # 100·(1 − ||y − ŷ|| / ||y − ȳ||) of the final model
    delay_samples: float  # input delay removed (samples at the analysis rate)
    modes: list[dict[str, Any]]  # per pole pair / real pole: natural_frequency_hz, damping_ratio
    warnings: list[str]
    converged: bool
    iterations: int
    order_selection: str  # "knee" (chosen from the losses) or "asked"
    knee_tolerance: float  # relative loss tolerance used for the knee
    preprocessing: dict[str, Any] = field(default_factory=dict)
    supported_band_hz: tuple[float, float] | None = None  # band the excitation supports
    noise: dict[str, float | None] = field(default_factory=dict)  # reference_rms, response_rms (channel units)
    order_evidence: dict[str, Any] = field(default_factory=dict)  # why this order

    @property
    def main_mode(self) -> dict[str, Any] | None:
        """The lowest supported complex pole pair (the sensor's main resonance), or None."""
        return main_mode(self.modes)

    @property
    def nonminimum_phase_zeros(self) -> np.ndarray:
        """Zeros on or outside the unit circle (a DCM must never invert them)."""
        z = self.model.zeros
        return z[np.abs(z) >= 1.0]

    def supported_poles(self) -> np.ndarray:
        """The poles of the supported modes (both poles of a pair): what a DCM may cancel."""
        keep = [complex(*m["pole"]) for m in self.modes if m["supported"]]
        poles = [p for q in keep for p in ((q, q.conjugate()) if q.imag > 0 else (q,))]
        return np.array(poles, dtype=complex)

    @property
    def sample_interval_s(self) -> float:
        return self.model.sample_interval_s

    @property
    def poles(self) -> np.ndarray:
        return self.model.poles

    @property
    def zeros(self) -> np.ndarray:
        return self.model.zeros

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields: the model JSON (DESIGN.md) plus the fit details; inf → None."""
        out = self.model.to_dict()
        out.update(
            {
                "loss_by_order": _finite_or_none(self.loss_by_order),
                "arx_loss_by_order": _finite_or_none(self.arx_loss_by_order),
                "aic_by_order": _finite_or_none(self.aic_by_order),
                "bic_by_order": _finite_or_none(self.bic_by_order),
                "order_selection": self.order_selection,
                "knee_tolerance": self.knee_tolerance,
                "fit_percent": _finite_or_none([self.fit_percent])[0],
                "modes": [dict(m) for m in self.modes],
                "converged": self.converged,
                "iterations": self.iterations,
                "warnings": list(self.warnings),
                "preprocessing": dict(self.preprocessing),
                "main_mode": dict(self.main_mode) if self.main_mode is not None else None,
                "supported_band_hz": list(self.supported_band_hz) if self.supported_band_hz else None,
                "nonminimum_phase_zeros": complex_pairs(self.nonminimum_phase_zeros),
                "noise": dict(self.noise),
                "order_evidence": dict(self.order_evidence),
            }
        )
        return out


def _finite_or_none(values: list[float]) -> list[float | None]:
    return [float(v) if v is not None and math.isfinite(v) else None for v in values]


def modes_of(
    poles: np.ndarray, sample_interval_s: float, supported_band_hz: tuple[float, float] | None = None
) -> list[dict[str, Any]]:
    """Natural frequency (Hz) and damping ratio per complex pole pair or real pole (s = ln(z)/T).

    Sorted by natural frequency. `kind` is "complex" (a pair, listed once with its positive
    imaginary part) or "real". A real pole gives a damping ratio of 1 (over-damped section with
    time constant 1/(2π·f_n)); a negative real pole sits at Nyquist (an artefact of the
    discretisation: `nyquist` True, never supported); a pole at the origin has no frequency.
    `supported`: the natural frequency lies inside `supported_band_hz` (the band the excitation
    supports; None: not judged, True).
    """
    modes = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag < 0:
            continue
        if p == 0:
            modes.append({"kind": "real", "pole": [0.0, 0.0], "natural_frequency_hz": None, "damping_ratio": None,
                          "nyquist": False, "supported": False})
            continue
        s = np.log(p) / sample_interval_s
        wn = float(abs(s))
        f_n = wn / (2 * np.pi)
        nyquist = bool(p.imag == 0 and p.real < 0)
        supported = not nyquist and (
            supported_band_hz is None or supported_band_hz[0] <= f_n <= supported_band_hz[1]
        )
        modes.append(
            {
                "kind": "complex" if p.imag > 0 else "real",
                "pole": [float(p.real), float(p.imag)],
                "natural_frequency_hz": f_n,
                "damping_ratio": float(-s.real / wn) if wn > 0 else None,
                "nyquist": nyquist,
                "supported": bool(supported),
            }
        )
    return sorted(modes, key=lambda m: m["natural_frequency_hz"] or 0.0)


def main_mode(modes: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The sensor's main mode: the lowest supported complex pole pair (None if there is none)."""
    pairs = [m for m in modes if m["kind"] == "complex" and m["supported"]]
    return min(pairs, key=lambda m: m["natural_frequency_hz"]) if pairs else None


def identify(
    record: Record,
    max_order: int = 12,
    order: int | None = None,
    sample_rate_hz: float | None = DEFAULT_ANALYSIS_RATE_HZ,
    *,
    knee_tolerance: float = 0.01,
    max_delay_samples: int = 32,
    remove_delay: bool = True,
    search_iterations: int = 5,
    max_iterations: int = 40,
    patience: int | None = 3,
) -> Identification:
    """Identify a discrete model of the accelerometer from a two-channel record.

    max_order: the largest order tried (losses are reported for 1 … max_order).
    order: fit exactly this order (errors if unstable or not converged; a warning if the data
        support only a lower order); None: choose it at the knee of the bias-corrected loss.
    sample_rate_hz: analysis rate; a faster record is resampled to it. None: use the record's.
    knee_tolerance: relative loss above the best order's that still counts as "no longer
        falling" (the chance improvement 2(2N+1) parameters could give is added to it).
    max_delay_samples: largest channel offset searched (samples at the analysis rate).
    remove_delay: False keeps the channels as recorded (delay 0).
    search_iterations / max_iterations: SRIV iterations per order while choosing / for the
        final order.
    patience: stop trying higher orders once this many past the knee gave no gain (their
        losses are NaN: not evaluated); None tries every order up to max_order.
    """
    if max_order < 1:
        raise AnalysisError(f"max_order must be at least 1, got {max_order}")
    if order is not None and order < 1:
        raise AnalysisError(f"order must be at least 1, got {order}")
    n_max = max(max_order, order or 0)
    warnings: list[str] = []
    pre: dict[str, Any] = {"record_sample_rate_hz": record.sample_rate_hz}

    rec = record if sample_rate_hz is None else resample_to_rate(record, sample_rate_hz)
    if rec is not record:
        pre["resampled_to_hz"] = rec.sample_rate_hz
    ref, resp = _checked_channels(rec)
    ref, resp, baselines = _remove_baselines(ref, resp)
    pre.update(baselines)
    quiet = int(baselines.get("baseline_samples", 0))
    noise = {
        "reference_rms": float(np.std(ref[:quiet])) if quiet else None,
        "response_rms": float(np.std(resp[:quiet])) if quiet else None,
    }
    try:
        band = supported_band_hz(ref, rec.sample_interval_s, noise["reference_rms"])
    except AnalysisError:
        band = None

    shifts: range | None = None
    xcorr = 0.0
    if remove_delay:
        shifts, xcorr = _shift_range(ref, resp, max_delay_samples)
        pre["cross_correlation_delay_samples"] = xcorr
    widest = max(abs(shifts.start), abs(shifts.stop - 1)) if shifts is not None else 0
    need = MIN_SAMPLES_PER_PARAMETER * (2 * n_max + 1)
    if ref.size - widest < need:
        what = f"order {order}" if order is not None and order >= max_order else f"max order {n_max}"
        raise AnalysisError(
            f"record too short for {what}: {ref.size} samples at the analysis rate, "
            f"need at least {need + widest} ({MIN_SAMPLES_PER_PARAMETER} per parameter, "
            "plus the delay searched)"
        )

    # Bias-corrected fit of every order, each at its own best delay (the SRIV fit alternates
    # with the delay; the search starts from the order-2 fit at the correlation peak).
    delay = 0
    if shifts is not None:
        start = min(max(round(xcorr), shifts.start), shifts.stop - 1)
        _, delay = _fit_at_best_delay(ref, resp, min(2, n_max), start, shifts, search_iterations)
    # Losses are compared per row (mean squared output error) while searching; `patience`
    # orders past the knee with no gain end the search (the rest stay NaN: not evaluated).
    tolerance = knee_tolerance + 2.0 * (2 * n_max + 1) / (ref.size - widest - n_max)
    floor = 1e-12 * long_dot(resp, resp) / ref.size
    fits: list[TransferFit | None] = [None] * n_max
    delays: list[int] = [delay] * n_max
    mean_losses = [float("nan")] * n_max
    for n in range(1, n_max + 1):
        fit, delay = _fit_at_best_delay(ref, resp, n, delay, shifts, search_iterations)
        fits[n - 1], delays[n - 1] = fit, delay
        # A fit that settles on an unstable estimate is no candidate (its reflected stand-in
        # may still fit tolerably, but it is not what the data say).
        mean_losses[n - 1] = float("inf") if fit.estimate_unstable else _mean_loss(fit, ref.size, delay)
        knee_so_far = _knee(mean_losses, tolerance, floor)
        must_reach = order or 0
        if patience is not None and knee_so_far is not None and n >= max(knee_so_far + patience, must_reach):
            break
    # Quoted as sums over the rows every order has in common.
    rows = ref.size - n_max - max(abs(d) for d in delays)
    losses = [v * rows for v in mean_losses]
    knee = _knee(losses, tolerance, floor * rows)
    if knee is None:
        raise AnalysisError(
            f"no stable model of order 1 … {n_max} fits this record (every bias-corrected fit was unstable)"
        )

    unsupported = ""
    if order is None:
        chosen, selection = knee, "knee"
    else:
        chosen, selection = order, "asked"
        if knee < order:
            drop = _relative_drop(losses, knee, order)
            unsupported = (
                f"the data support only order {knee}: the bias-corrected loss falls by {drop:.2%} from "
                f"order {knee} to {order} (tolerance {tolerance:.2%}); the extra poles are not "
                "determined by this record (a mode beyond the excitation's band?)"
            )
            warnings.append(f"order {order} was asked but {unsupported}")

    delay = delays[chosen - 1]
    u, y = remove_input_delay(ref, resp, delay)
    chosen_fit = fits[chosen - 1]
    assert chosen_fit is not None  # the knee and an asked order are always evaluated
    final = _finish(u, y, chosen_fit, max_iterations)
    if order is not None:
        if not _acceptable(final):
            why = unsupported if knee < order else "is the response really the sensor's answer to this reference?"
            raise AnalysisError(
                f"the order-{order} fit is unstable: the estimate settles with a pole on or outside the "
                f"unit circle ({why})"
            )
        if not final.converged:
            raise AnalysisError(
                f"the order-{order} fit did not converge in {final.iterations} iterations; try a lower order"
            )
    elif not _acceptable(final):
        final, chosen = _stable_fallback(ref, resp, fits, delays, chosen, losses, max_iterations, warnings)
        delay = delays[chosen - 1]
        u, y = remove_input_delay(ref, resp, delay)
    losses[chosen - 1] = min(losses[chosen - 1], _mean_loss(final, ref.size, delay) * rows)
    aic, bic = _information_criteria(losses, rows)
    # Plain least squares at the final delay, every order from one factorisation: reported
    # beside the bias-corrected losses (it keeps falling, so it cannot choose the order).
    arx_losses = [float(v) for v in arx_loss_by_order(u, y, n_max)]

    dt = rec.sample_interval_s
    model = DiscreteModel(dt, final.a, final.b, float(delay), info={"fit_method": final.method})
    pre["response_offset_fitted"] = final.offset
    fit = fit_percent(y, simulate(u, final.a, final.b) + final.offset)
    modes = modes_of(model.poles, dt, band)
    warnings += _excitation_warnings(u, dt, modes)
    if fit < POOR_FIT_PERCENT:
        warnings.append(
            f"the model explains only {fit:.1f} % of the response (fit = 100·(1 − ‖y − ŷ‖/‖y − ȳ‖)): "
            "check that the channels belong together and that the response is not mostly noise"
        )
    if final.reflected:
        warnings.append(
            f"the order-{chosen} fit had poles outside the unit circle during the iteration; they were "
            "reflected inside (spare poles nearly cancelling zeros: a lower order may be enough)"
        )
    if not final.converged:
        warnings.append(
            f"the order-{chosen} fit did not fully converge in {final.iterations} iterations "
            "(its loss was the lowest reached)"
        )
    model.info.update(
        {"loss_by_order": losses, "fit_percent": fit, "converged": final.converged, "warnings": warnings}
    )
    return Identification(
        model=model,
        order=chosen,
        loss_by_order=losses,
        arx_loss_by_order=arx_losses,
        aic_by_order=aic,
        bic_by_order=bic,
        fit_percent=fit,
        delay_samples=float(delay),
        modes=modes,
        warnings=warnings,
        converged=final.converged,
        iterations=final.iterations,
        order_selection=selection,
        knee_tolerance=tolerance,
        preprocessing=pre,
        supported_band_hz=band,
        noise=noise,
        order_evidence={"criterion": selection, "knee_order": knee, "tolerance": tolerance,
                        "loss_by_order": _finite_or_none(losses)},
    )


def _checked_channels(rec: Record) -> tuple[np.ndarray, np.ndarray]:
    ref = np.asarray(rec.reference, dtype=float).ravel()
    resp = np.asarray(rec.response, dtype=float).ravel()
    for name, x in (("reference", ref), ("response", resp)):
        if not np.all(np.isfinite(x)):
            bad = int(np.flatnonzero(~np.isfinite(x))[0])
            raise AnalysisError(f"the {name} channel has a NaN or infinite value at sample {bad}")
    if ref.size != resp.size:
        raise AnalysisError(f"the channels differ in length ({ref.size} and {resp.size} samples)")
    for name, x in (("reference", ref), ("response", resp)):
        if x.size == 0 or np.ptp(x) == 0:
            raise AnalysisError(f"the {name} channel is flat (constant): there is nothing to identify")
    return ref, resp


def _remove_baselines(ref: np.ndarray, resp: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Subtract each channel's mean over the quiet lead-in before the reference pulse.

    The pulse starts where |reference| first exceeds 10 % of its peak (about its median);
    the lead-in ends a margin before that. Without 16 quiet samples nothing is removed.
    """
    centred = np.abs(ref - np.median(ref))
    start = int(np.argmax(centred > 0.1 * np.max(centred)))
    margin = max(4, start // 10)
    quiet = start - margin
    if quiet < 16:
        return ref, resp, {"baseline_removed": False}
    ref_base = float(np.mean(ref[:quiet]))
    resp_base = float(np.mean(resp[:quiet]))
    return (
        ref - ref_base,
        resp - resp_base,
        {"baseline_removed": True, "reference_baseline": ref_base, "response_baseline": resp_base,
         "baseline_samples": quiet},
    )


def remove_input_delay(ref: np.ndarray, resp: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) with y(k) = response(k + d) against u(k) = reference(k): removes a delay of d samples."""
    if d >= 0:
        return ref[: ref.size - d], resp[d:]
    return ref[-d:], resp[: resp.size + d]


def fit_percent(measured: np.ndarray, simulated: np.ndarray) -> float:
    """100·(1 − ‖y − ŷ‖/‖y − ȳ‖): 100 is a perfect fit, 0 no better than the mean; NaN for a constant y."""
    y = np.asarray(measured, dtype=float)
    centred, error = y - np.mean(y), y - np.asarray(simulated, dtype=float)
    spread = math.sqrt(long_dot(centred, centred))
    return 100.0 * (1.0 - math.sqrt(long_dot(error, error)) / spread) if spread > 0 else float("nan")


def _shift_range(ref: np.ndarray, resp: np.ndarray, max_lag: int) -> tuple[range, float]:
    """Input delays worth trying, and the cross-correlation delay that bounds them.

    The cross-correlation peak includes the sensor's own response time (for a 27 kHz
    resonance and a 10 µs pulse it sits ~10 samples after the pure delay), so it is only an
    upper bound: shifts from −max_lag to one past the peak are allowed.
    """
    max_lag = int(max(1, min(max_lag, ref.size // 4)))
    xcorr = estimate_delay_samples(ref, resp, max_lag)
    return range(-max_lag, min(max_lag, math.ceil(xcorr) + 1) + 1), xcorr


def _best_shift_for_denominator(
    a: np.ndarray, ref: np.ndarray, resp: np.ndarray, nb: int, shifts: range
) -> tuple[int, np.ndarray]:
    """The delay d (and B) minimising Σ (y(k) − B(d⁻¹)·(u/A)(k − d))² with A held fixed.

    With A fixed the output error is linear in B, so every shift is scored at once from the
    autocorrelation of u/A (a Toeplitz system, scipy.linalg.solve_toeplitz) and its
    cross-correlation with the response over the whole record (records start and end near
    rest, so end effects are ignored). Alternating this with the SRIV fit minimises the
    output error over the coefficients and the delay together.
    """
    length = ref.size
    u_f = signal.lfilter([1.0], stabilised(a), ref)
    auto = np.array([long_dot(u_f[: length - t], u_f[t:]) for t in range(nb)])
    lags = range(shifts.start, shifts.stop - 1 + nb)
    cross = np.array(
        [long_dot(resp[m:], u_f[: length - m]) if m >= 0 else long_dot(resp[: length + m], u_f[-m:]) for m in lags]
    )
    windows = sliding_window_view(cross, nb)  # row i: c(d), …, c(d + nb − 1) for d = shifts[i]
    try:
        coef = linalg.solve_toeplitz(auto, windows.T)
    except (linalg.LinAlgError, ValueError):
        return shifts.start, np.zeros(nb)
    explained = np.einsum("ij,ji->i", windows, coef)
    i = int(np.argmax(explained))
    return shifts[i], coef[:, i]


def _fit_at_best_delay(
    ref: np.ndarray,
    resp: np.ndarray,
    order: int,
    delay: int,
    shifts: range | None,
    iterations: int,
) -> tuple[TransferFit, int]:
    """SRIV fit of `order`, alternated with the best delay for its denominator (≤ 4 rounds).

    Starts from least squares at `delay`; after a move, from the fitted A and the B that
    went with the new delay. Returns the fit with the lowest loss per row and its delay.
    """
    start: tuple[np.ndarray, np.ndarray] | None = None
    best_fit: tuple[TransferFit, int] | None = None
    tried: set[int] = set()
    for _ in range(4):
        u, y = remove_input_delay(ref, resp, delay)
        a0, b0 = start if start is not None else arx_coefficients_by_order(u, y, order)[-1]
        fit = refined_iv_fit(u, y, a0, b0, max_iterations=iterations)
        tried.add(delay)
        if best_fit is None or _mean_loss(fit, ref.size, delay) < _mean_loss(best_fit[0], ref.size, best_fit[1]):
            best_fit = (fit, delay)
        if shifts is None or not fit.stable:
            break
        best, b_best = _best_shift_for_denominator(fit.a, ref, resp, order + 1, shifts)
        if best in tried:
            break
        delay, start = best, (fit.a, b_best)
    assert best_fit is not None
    return best_fit


def _mean_loss(fit: TransferFit, n_samples: int, delay: int) -> float:
    """Output-error loss per row of a fit on the record shifted by `delay`."""
    rows = n_samples - abs(delay) - fit.order
    return fit.oe_loss / rows if rows > 0 else float("inf")


def _information_criteria(losses: list[float], rows: int) -> tuple[list[float], list[float]]:
    aic, bic = [], []
    for n, loss in enumerate(losses, start=1):
        p = 2 * n + 1
        if math.isfinite(loss) and loss > 0:
            base = rows * math.log(loss / rows)
            aic.append(base + 2 * p)
            bic.append(base + p * math.log(rows))
        else:
            aic.append(float("inf"))
            bic.append(float("inf"))
    return aic, bic


def _knee(losses: list[float], tolerance: float, floor: float) -> int | None:
    """Smallest order whose loss is within `tolerance` (relative, plus `floor`) of the best."""
    finite = [v for v in losses if math.isfinite(v)]
    if not finite:
        return None
    best = min(finite)
    for n, loss in enumerate(losses, start=1):
        if math.isfinite(loss) and loss <= best * (1 + tolerance) + floor:
            return n
    return None


def _relative_drop(losses: list[float], low: int, high: int) -> float:
    a, b = losses[low - 1], losses[high - 1]
    if not (math.isfinite(a) and math.isfinite(b)) or a <= 0:
        return float("nan")
    return (a - b) / a


def _finish(u: np.ndarray, y: np.ndarray, start: TransferFit, max_iterations: int) -> TransferFit:
    """Iterate SRIV to convergence from the search fit; if it will not settle, polish the
    best iterate by minimising the output error directly (which has a clean stopping rule)."""
    if not start.stable:
        return start
    fit = refined_iv_fit(u, y, start.a, start.b, max_iterations=max_iterations)
    unstable = fit.estimate_unstable
    if not fit.stable or fit.oe_loss > start.oe_loss:
        fit = start
    if fit.converged and not unstable:
        return replace(fit, iterations=start.iterations + fit.iterations, converged=True)
    polished = output_error_refine(u, y, fit)
    return replace(
        polished, iterations=start.iterations + fit.iterations, estimate_unstable=unstable or fit.estimate_unstable
    )


def _acceptable(fit: TransferFit) -> bool:
    """Stable, not settled on an unstable estimate, and not hugging the unit circle."""
    if not fit.stable or fit.estimate_unstable:
        return False
    return fit.order == 0 or float(np.max(np.abs(np.roots(fit.a)))) < 1.0 - MARGINAL_POLE


def _stable_fallback(
    ref: np.ndarray,
    resp: np.ndarray,
    fits: list[TransferFit | None],
    delays: list[int],
    chosen: int,
    losses: list[float],
    max_iterations: int,
    warnings: list[str],
) -> tuple[TransferFit, int]:
    """When the knee order's final fit fails, fall back to the other orders (best loss first)."""
    candidates = sorted(
        (n for n in range(1, len(fits) + 1) if n != chosen and fits[n - 1] is not None and math.isfinite(losses[n - 1])),
        key=lambda n: (losses[n - 1], n),
    )
    for n in candidates:
        u, y = remove_input_delay(ref, resp, delays[n - 1])
        start = fits[n - 1]
        assert start is not None
        fit = _finish(u, y, start, max_iterations)
        if _acceptable(fit):
            warnings.append(f"the order-{chosen} fit became unstable; order {n} (next best loss) is used")
            return fit, n
    raise AnalysisError(
        "no order gives a stable model for this record (every fit settles with a pole on or outside "
        "the unit circle)"
    )


def _excitation_warnings(u: np.ndarray, dt: float, modes: list[dict[str, Any]]) -> list[str]:
    """Warn about modes in a band the reference does not excite (the data cannot support them)."""
    spectrum = np.abs(fft.rfft(u))
    freqs = fft.rfftfreq(u.size, dt)
    peak = float(np.max(spectrum)) if spectrum.size else 0.0
    out = []
    if peak <= 0:
        return out
    for m in modes:
        f = m.get("natural_frequency_hz")
        if f is None or m["kind"] != "complex":
            continue
        band = (freqs >= f / 1.25) & (freqs <= f * 1.25)
        if not np.any(band):
            continue
        level = float(np.sqrt(np.mean(spectrum[band] ** 2))) / peak
        if level < EXCITATION_FLOOR:
            out.append(
                f"the mode at {f / 1e3:.4g} kHz lies where the reference is {20 * math.log10(max(level, 1e-300)):.0f} dB "
                "below its spectral peak: this record cannot determine it"
            )
    return out
