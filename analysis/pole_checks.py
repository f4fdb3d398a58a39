"""Poles as people write them (0.974+0.1396j), and the checks a list of poles must pass."""

from __future__ import annotations

import math

import numpy as np

from hopkinson.analysis.errors import AnalysisError
from hopkinson.analysis.options import CONJUGATE_TOLERANCE

_CONJ_TOL = CONJUGATE_TOLERANCE  # the rule AnalysisOptions.check() applies to extra poles too


def format_complex(value: complex) -> str:
    """A pole as people write it: 0.974+0.1396j (real poles without the j part)."""
    v = complex(value)
    return f"{v.real:.6g}" if v.imag == 0 else f"{v.real:.6g}{v.imag:+.6g}j"


def parse_complex(text: str, option: str) -> complex:
    """One pole such as 0.974+0.1396j, 0.974-0.1396i or 0.5 (the inverse of `format_complex`);
    AnalysisError naming `option` otherwise."""
    raw = text.strip().replace(" ", "")
    if not raw:
        raise AnalysisError(f"{option}: empty pole in the list (write poles like 0.974+0.1396j, comma-separated)")
    try:
        value = complex(raw.replace("i", "j").replace("I", "j").replace("J", "j"))
    except ValueError:
        raise AnalysisError(f"{option}: {text.strip()!r} is not a complex number (write poles like 0.974+0.1396j)") from None
    if not (math.isfinite(value.real) and math.isfinite(value.imag)):
        raise AnalysisError(f"{option}: {text.strip()!r} is not a finite number")
    return value


def parse_poles(text: str, option: str) -> np.ndarray:
    """A comma-separated list of poles (what `hopkinson dcm --poles` and the panel accept)."""
    return np.array([parse_complex(part, option) for part in text.split(",")], dtype=complex)


def check_conjugate_pairs(values: np.ndarray, what: str) -> None:
    """Raise unless every complex value has its conjugate partner (real coefficients)."""
    v = list(np.atleast_1d(np.asarray(values, dtype=complex)))
    unmatched = [x for x in v if abs(x.imag) > _CONJ_TOL * max(1.0, abs(x))]
    while unmatched:
        x = unmatched.pop(0)
        partner = next((i for i, y in enumerate(unmatched) if abs(y - np.conj(x)) <= _CONJ_TOL * max(1.0, abs(x))), None)
        if partner is None:
            raise AnalysisError(
                f"{what}: {format_complex(x)} has no conjugate partner {format_complex(np.conj(x))}; "
                "list both members of every complex pair"
            )
        unmatched.pop(partner)


def check_inside_unit_circle(values: np.ndarray, what: str) -> None:
    """Raise unless every value lies strictly inside the unit circle (a stable pole)."""
    for x in np.atleast_1d(np.asarray(values, dtype=complex)):
        if not abs(x) < 1.0:
            raise AnalysisError(f"{what}: {format_complex(x)} is on or outside the unit circle (|p| = {abs(x):.6g}); the filter would be unstable")

