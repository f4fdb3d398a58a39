"""One shot as asked for and as it ended, and the shot pipeline after the capture:
raw data stored first (atomically), then analysed; an analysis failure is recorded in the
file and never loses the shot.

- ShotRequest: what to fire (pressure, projectile), who and what is calibrated, analysis
  options (None = the configuration's value), where the file goes, and how long ARM waits
  for the fire confirmation.
- ShotOutcome: how it ended (final state, file, results, error, exit code, the state it was
  aborted in, whether the fire command was sent). `raise_for_outcome()` raises ShotAborted
  with the one-line message for exit code 3.
- store_raw_shot / analyse_raw / record_analysis: the STORE and ANALYSE steps of the sequencer
  (and of a campaign analysing a recorded shot from its file).

Analysis failures. When the analysis raises (bad data, a fit the data cannot support, a
bug), the shot file keeps its raw data and gets an /analysis group with status "failed" and
the error text; the shot still ends DONE (it was fired and recorded) with
`ShotOutcome.analysis_error` set, and the command line exits 0 after printing that error.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
from hopkinson.analysis.records import Record
from hopkinson.drivers.digitizer import Waveform
from hopkinson.rig.config import RigConfig
from hopkinson.rig.errors import ConfigError, ShotAborted
from hopkinson.rig.shotfile import (
    PLAIN_NAME_RE,
    RawChannel,
    RawShot,
    ShotMeta,
    add_analysis,
    write_raw_shot,
)

EXIT_DONE = 0
EXIT_ABORTED = 3


class ShotRequestError(ConfigError):
    """A shot request that cannot be fired as asked (exit code 2, nothing was done)."""


@dataclass(frozen=True)
class ShotRequest:
    """What to fire and how to analyse it (None = the rig configuration's value)."""

    pressure_bar: float
    projectile: int = 3
    operator: str = ""
    accelerometer_model: str = ""
    accelerometer_serial: str = ""
    sensitivity_v_per_m_s2: float | None = None  # None -> config [analysis]
    max_order: int | None = None  # analysis options; None -> the analysis' defaults
    sample_rate_hz: float | None = None  # analysis rate; None -> config [analysis]
    dcm_ratio: float | None = None
    dcm_damping: float | None = None
    out_dir: Path = Path("shots")
    shot_name: str | None = None  # None -> "shot-<UTC time>-<8 hex>"
    campaign_id: str | None = None
    shot_id: str | None = None
    shot_index: int | None = None
    confirm_timeout_s: float | None = None  # how long ARM waits for the fire confirmation; None -> timeouts.arm_s

    def check(self, config: RigConfig) -> None:
        """Raise ShotRequestError (naming the field and the reason) unless the request is firable."""
        limits = config.limits
        p = self.pressure_bar
        if not (isinstance(p, int | float) and math.isfinite(p)):
            raise ShotRequestError(f"pressure_bar: must be a number, got {p!r}")
        if not limits.min_pressure_bar <= p <= limits.max_pressure_bar:
            raise ShotRequestError(f"pressure_bar: {p:g} bar is outside the rig's limits "
                                   f"{limits.min_pressure_bar:g} .. {limits.max_pressure_bar:g} bar "
                                   f"({config.path or 'configuration'} [limits])")
        if self.projectile not in (1, 2, 3) or isinstance(self.projectile, bool):
            raise ShotRequestError(f"projectile: must be 1, 2 or 3, got {self.projectile!r}")
        for name in ("sensitivity_v_per_m_s2", "sample_rate_hz", "dcm_ratio", "dcm_damping"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ShotRequestError(f"{name}: must be a positive number, got {value!r}")
        if self.max_order is not None and not (isinstance(self.max_order, int) and 1 <= self.max_order <= 60):
            raise ShotRequestError(f"max_order: must be an integer 1..60, got {self.max_order!r}")
        if self.confirm_timeout_s is not None and not (
                isinstance(self.confirm_timeout_s, int | float) and 0 <= self.confirm_timeout_s <= 3600):
            raise ShotRequestError(f"confirm_timeout_s: must be 0..3600 s, got {self.confirm_timeout_s!r}")
        if self.shot_name is not None and not PLAIN_NAME_RE.match(self.shot_name):
            raise ShotRequestError(f"shot_name: {self.shot_name!r} is not a plain file name "
                                   "(letters, digits, '_', '.', '-')")
        if not Path(self.out_dir).is_dir():
            raise ShotRequestError(f"out_dir: {self.out_dir} is not an existing folder")

    def shot_path(self) -> Path:
        """Where the shot file goes: out_dir / <shot_name or a generated name>.h5."""
        name = self.shot_name or generated_shot_name()
        return Path(self.out_dir) / f"{name}.h5"

    def sensitivity(self, config: RigConfig) -> float:
        return self.sensitivity_v_per_m_s2 if self.sensitivity_v_per_m_s2 is not None \
            else config.analysis.sensitivity_v_per_m_s2

    def analysis_options(self) -> dict[str, Any]:
        """The analysis options given (None left out)."""
        keys = ("max_order", "sample_rate_hz", "dcm_ratio", "dcm_damping")
        return {k: getattr(self, k) for k in keys if getattr(self, k) is not None}


def generated_shot_name(now: datetime | None = None) -> str:
    """"shot-20250101T120000Z-1a2b3c4d": UTC time of the request and 8 random hex digits."""
    now = now or datetime.now(UTC)
    return f"shot-{now.strftime('%Y%m%dT%H%M%SZ')}-{uuid.uuid4().hex[:8]}"


@dataclass(frozen=True)
class ShotOutcome:
    """How a shot ended.

    final_state: "DONE", "ABORTED" or "FAULT" (FAULT: the safe state could not be confirmed).
    error: the one-line message when the shot did not complete (None when DONE).
    analysis_error: set when the shot was recorded but its analysis failed (still DONE).
    fired: the fire command was sent (the projectile may have been launched).
    aborted_in: the state in which the abort began (None when DONE).
    """

    final_state: str
    shot_path: Path | None = None
    results: dict[str, Any] | None = None
    error: str | None = None
    exit_code: int = EXIT_DONE
    aborted_in: str | None = None
    fired: bool = False
    analysis_error: str | None = None
    safe_confirmed: bool = True
    warnings: tuple[str, ...] = ()

    @property
    def done(self) -> bool:
        return self.final_state == "DONE"

    def raise_for_outcome(self) -> None:
        """Raise ShotAborted (exit code 3, the one-line message) unless the shot is DONE."""
        if not self.done:
            raise ShotAborted(self.error or f"shot ended in {self.final_state}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the `--json` output of `hopkinson shot`)."""
        out = asdict(self)
        out["shot_path"] = str(self.shot_path) if self.shot_path is not None else None
        out["warnings"] = list(self.warnings)
        return out


@dataclass(frozen=True)
class CapturedShot:
    """What the digitizer recorded, with the settings it was recorded under."""

    doppler: Waveform
    response: Waveform
    settings: dict[str, Any] = field(default_factory=dict)  # amplifier read-back, pressure at fire, ...
    truth: dict[str, Any] | None = None  # simulated truth (simulation only)

    def raw_shot(self) -> RawShot:
        """The two channels as a RawShot (int16 codes exactly as recorded, with their scaling)."""
        d, r = self.doppler, self.response
        if d.codes.size != r.codes.size or d.trigger_index != r.trigger_index or not math.isclose(
                d.sample_interval_s, r.sample_interval_s, rel_tol=1e-9):
            raise ValueError("the two channels differ in length, trigger index or sample interval")
        return RawShot(
            channels={
                "doppler": RawChannel(np.asarray(d.codes, dtype=np.int16), d.scale_v, d.offset_v),
                "response": RawChannel(np.asarray(r.codes, dtype=np.int16), r.scale_v, r.offset_v),
            },
            sample_interval_s=d.sample_interval_s,
            trigger_index=d.trigger_index,
        )


def shot_meta(request: ShotRequest, config: RigConfig, identities: dict[str, str],
              captured: CapturedShot) -> ShotMeta:
    """The shot file's meta: the request's who/what, a full configuration snapshot plus the
    settings this shot ran with (under "shot_settings"), instrument identities, truth."""
    snapshot = config.snapshot()
    snapshot["shot_settings"] = dict(captured.settings,
                                     sensitivity_v_per_m_s2=request.sensitivity(config),
                                     analysis_options=request.analysis_options())
    return ShotMeta(
        operator=request.operator,
        accelerometer_model=request.accelerometer_model,
        accelerometer_serial=request.accelerometer_serial,
        pressure_bar=float(request.pressure_bar),
        projectile=int(request.projectile),
        instruments=dict(identities),
        config=snapshot,
        shot_id=request.shot_id,
        shot_index=request.shot_index,
        campaign_id=request.campaign_id,
        simulated_truth=captured.truth,
    )


def store_raw_shot(path: Path, captured: CapturedShot, meta: ShotMeta) -> Path:
    """STORE: write the raw shot atomically (tmp, flush, fsync, rename) before any analysis."""
    return write_raw_shot(path, captured.raw_shot(), meta)


@dataclass(frozen=True)
class AnalysisResult:
    """What the analysis gives back to be stored: results dict and the reduced record."""

    results: dict[str, Any]
    record: Record | None = None


def analysis_params(request: ShotRequest, config: RigConfig, settings: dict[str, Any]) -> dict[str, Any]:
    """Everything the analysis needs besides the two channels: the rig's constants and the
    request's options, keyed as analysis.shot_analysis.AnalysisParams (None = its default)."""
    a = config.analysis
    return {
        "grating_pitch_m": a.grating_pitch_m,
        "orders": tuple(a.orders),
        "amp_gain": float(settings.get("amplifier_gain", config.amplifier.gain)),
        "sensitivity_v_per_m_s2": request.sensitivity(config),
        "sample_rate_hz": request.sample_rate_hz or a.sample_rate_hz,
        "max_order": request.max_order,
        "dcm_ratio": request.dcm_ratio,
        "dcm_damping": request.dcm_damping,
    }


def analyse_raw(raw: RawShot, params: dict[str, Any]) -> AnalysisResult:
    """ANALYSE, the computation only (pure; runs in a worker thread): the shared shot
    analysis (analysis.shot_analysis) of the raw channels in volts."""
    from hopkinson.analysis.shot_analysis import (  # heavy: loaded when needed
        AnalysisParams,
        analyse_raw_shot,
    )

    analysis = analyse_raw_shot(raw.volts("doppler"), raw.volts("response"), raw.sample_interval_s,
                                AnalysisParams.from_options(**params))
    return AnalysisResult(analysis.to_dict(), analysis.record)


def analysis_error_text(exc: BaseException) -> str:
    """The one-line error of an analysis that raised: a ValueError (bad data, a fit the data
    cannot support) says why; anything else also names its type."""
    if isinstance(exc, ValueError):
        return f"analysis failed: {exc}"
    return f"analysis failed: {type(exc).__name__}: {exc}"


def record_analysis(path: Path, outcome: AnalysisResult | None, error: str | None) -> None:
    """Store the analysis (or its failure) in the shot file, atomically; raw data untouched."""
    if error is not None:
        add_analysis(path, outcome.results if outcome is not None else {}, error=error)
    else:
        assert outcome is not None
        add_analysis(path, outcome.results, record=outcome.record)


AnalyseFn = Callable[[RawShot, dict[str, Any]], AnalysisResult]
