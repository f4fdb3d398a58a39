"""The discrete dynamic model A(d⁻¹)·y(k) = B(d⁻¹)·u(k − delay) and its JSON form.

a[0] = 1. Coefficients are in powers of the backshift operator d⁻¹ (= z⁻¹), so the
transfer function is H(z) = B(z⁻¹)/A(z⁻¹) and `scipy.signal.lfilter(b, a, u)` simulates it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hopkinson.analysis.errors import AnalysisError


def complex_pairs(values: np.ndarray) -> list[list[float]]:
    """Complex numbers as [re, im] pairs for JSON."""
    return [[float(np.real(v)), float(np.imag(v))] for v in np.asarray(values, dtype=complex)]


def from_pairs(pairs: Any, what: str) -> np.ndarray:
    """[re, im] pairs back to complex numbers; `what` names the field in errors."""
    try:
        arr = np.asarray(pairs, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError):
        raise AnalysisError(f"{what}: expected a list of [re, im] pairs") from None
    return arr[:, 0] + 1j * arr[:, 1]


def all_pole_numerator(order: int) -> np.ndarray:
    """B's shape for an all-pole model of `order`: (1 + z⁻¹)ⁿ/2ⁿ (unit gain at DC), the bilinear
    image of a continuous system with no finite zeros (a mass–spring sensor whose resonance
    lies beyond the band, a low-pass): zeros at Nyquist only, so no zero can follow a ripple."""
    return np.array([math.comb(order, i) for i in range(order + 1)], dtype=float) / 2.0**order


@dataclass(frozen=True)
class DiscreteModel:
    """A discrete transfer function with its sample interval and input delay."""

    sample_interval_s: float
    a: np.ndarray  # denominator A(d⁻¹), a[0] = 1
    b: np.ndarray  # numerator B(d⁻¹), b[0] is the direct term
    delay_samples: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)  # fit details (loss by order, fit %, …)

    def __post_init__(self) -> None:
        a = np.atleast_1d(np.asarray(self.a, dtype=float))
        b = np.atleast_1d(np.asarray(self.b, dtype=float))
        if a.size == 0 or a[0] == 0:
            raise AnalysisError("model: a[0] must be non-zero")
        object.__setattr__(self, "b", b / a[0])
        object.__setattr__(self, "a", a / a[0])

    @property
    def order(self) -> int:
        return int(self.a.size - 1)

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.a) if self.order > 0 else np.array([], dtype=complex)

    @property
    def zeros(self) -> np.ndarray:
        """Roots of B; exactly −1 (n times) when B ∝ (1 + d⁻¹)ⁿ, the all-pole structure's
        numerator (np.roots scatters a multiple root: ~1e-4 off the circle at n = 4)."""
        b = np.trim_zeros(self.b, "b")
        if b.size <= 1:
            return np.array([], dtype=complex)
        n = b.size - 1
        total = float(np.sum(b))
        if total != 0.0 and np.allclose(b / total, all_pole_numerator(n), rtol=1e-9, atol=1e-12):
            return np.full(n, -1.0 + 0.0j)
        return np.roots(b)

    @property
    def nonminimum_phase_zeros(self) -> np.ndarray:
        """Zeros on or outside the unit circle (a DCM must never invert them), less those at
        z = −1: the all-pole structure's, at Nyquist, beyond every band."""
        z = self.zeros
        return z[(np.abs(z) >= 1.0) & (z != -1.0)]

    @property
    def dc_gain(self) -> float:
        den = float(np.sum(self.a))
        if den == 0:
            raise AnalysisError("model has a pole at z = 1: no DC gain")
        return float(np.sum(self.b) / den)

    @property
    def is_stable(self) -> bool:
        return bool(np.all(np.abs(self.poles) < 1.0))

    def to_dict(self) -> dict[str, Any]:
        """The model JSON fields (docs/files-and-formats.md, 'Model / DCM JSON')."""
        return {
            "sample_interval_s": self.sample_interval_s,
            "order": self.order,
            "a": [float(x) for x in self.a],
            "b": [float(x) for x in self.b],
            "delay_samples": float(self.delay_samples),
            "poles": complex_pairs(self.poles),
            "zeros": complex_pairs(self.zeros),
            "dc_gain": self.dc_gain,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "model") -> DiscreteModel:
        """Build from the JSON fields; `source` names the file in errors."""
        for key in ("sample_interval_s", "a", "b"):
            if key not in data:
                raise AnalysisError(f"{source}: missing key '{key}'")
        try:
            dt = float(data["sample_interval_s"])
            a = np.asarray(data["a"], dtype=float)
            b = np.asarray(data["b"], dtype=float)
        except (TypeError, ValueError):
            raise AnalysisError(f"{source}: sample_interval_s, a and b must be numbers") from None
        if not dt > 0:
            raise AnalysisError(f"{source}: sample_interval_s must be positive")
        if a.ndim != 1 or b.ndim != 1 or not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise AnalysisError(f"{source}: a and b must be flat lists of finite numbers")
        return cls(dt, a, b, float(data.get("delay_samples", 0.0)))


def load_json_object(path: str | Path, what: str) -> dict[str, Any]:
    """Read a JSON file that must hold one object; `what` names the kind of file in errors."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise AnalysisError(f"{path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise AnalysisError(f"{path}: not a JSON {what} file ({exc})") from None
    except RecursionError:
        raise AnalysisError(f"{path}: not a JSON {what} file (nested too deeply to be one)") from None
    except OSError as exc:
        raise AnalysisError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not isinstance(data, dict):
        raise AnalysisError(f"{path}: expected a JSON object")
    return data


def load_model(path: str | Path) -> DiscreteModel:
    """Read a model JSON file written by `hopkinson identify -o` (under "model" or at top level)."""
    data = load_json_object(path, "model")
    return DiscreteModel.from_dict(data.get("model", data), source=str(path))
