"""The modes of a discrete model (the claim stage of analysis.identify_stages): each pole pair or real
pole as a natural frequency and damping ratio, whether the excitation's band supports it, and
whether a zero nearly cancels it (a pole–zero doublet: no mode)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields, replace
from enum import StrEnum
from typing import Any

import numpy as np

# A pole pair damped more than this is no resonance (it shapes the response without a peak that
# could be called the sensor's natural frequency): never a mode claimed, never the main mode.
RESONANCE_MAX_DAMPING = 0.3
# A zero closer to a pole than this fraction of the pole's distance to the unit circle cancels it
# (a pole–zero doublet changes the response by at most about that fraction near the pole).
DOUBLET_DISTANCE = 0.5


class ModeKind(StrEnum):
    """A complex pole pair (listed once, by its pole of positive imaginary part) or a real pole."""

    COMPLEX = "complex"
    REAL = "real"


@dataclass(frozen=True)
class Mode(Mapping[str, Any]):
    """One pole pair or real pole of a model and what may be claimed of it.

    natural_frequency_hz, damping_ratio: of s = ln(z)/T (None for a pole at the origin).
    nyquist: a negative real pole (an artefact of the discretisation, never supported).
    supported: the natural frequency lies inside the band the excitation supports.
    resonance: a complex pair damped at most RESONANCE_MAX_DAMPING (None: not judged).
    cancelled: a zero nearly cancels it (`mark_doublets`; None: not yet judged).
    shapes_band: the all-pole structure's resonance beyond the band (analysis.claims).
    Read like its JSON entry (`mode["supported"]`, `to_dict`): a field that is None (False for
    shapes_band) is not in it.
    """

    kind: ModeKind
    pole: tuple[float, float]
    natural_frequency_hz: float | None
    damping_ratio: float | None
    nyquist: bool
    supported: bool
    resonance: bool | None = None
    cancelled: bool | None = None
    shapes_band: bool = False

    def to_dict(self) -> dict[str, Any]:
        """The JSON entry: the fields set, the pole as [re, im]."""
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None and f.name in ("resonance", "cancelled") or f.name == "shapes_band" and not value:
                continue
            out[f.name] = list(value) if f.name == "pole" else str(value) if f.name == "kind" else value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Mode:
        """From a JSON entry (a results file's or a model file's; older ones lack some keys)."""
        pole = data["pole"]
        return cls(ModeKind(data.get("kind", "complex" if float(pole[1]) else "real")),
                   (float(pole[0]), float(pole[1])), data.get("natural_frequency_hz"),
                   data.get("damping_ratio"), bool(data.get("nyquist", False)), bool(data.get("supported", True)),
                   data.get("resonance"), data.get("cancelled"), bool(data.get("shapes_band", False)))

    @property
    def pole_z(self) -> complex:
        return complex(*self.pole)

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())


def modes_of(
    poles: np.ndarray, sample_interval_s: float, supported_band_hz: tuple[float, float] | None = None
) -> list[Mode]:
    """Natural frequency (Hz) and damping ratio per complex pole pair or real pole (s = ln(z)/T).

    Sorted by natural frequency. `kind` is "complex" (a pair, listed once with its positive
    imaginary part) or "real". A real pole gives a damping ratio of 1 (over-damped section with
    time constant 1/(2π·f_n)); a negative real pole sits at Nyquist (an artefact of the
    discretisation: `nyquist` True, never supported); a pole at the origin has no frequency.
    `supported`: the natural frequency lies inside `supported_band_hz` (the band the excitation
    supports; None: not judged, True). `resonance`: a complex pair damped at most
    RESONANCE_MAX_DAMPING (only a resonance is ever claimed as a mode).
    """
    modes = []
    for p in np.asarray(poles, dtype=complex):
        if p.imag < 0:
            continue
        if p == 0:
            modes.append(Mode(ModeKind.REAL, (0.0, 0.0), None, None, nyquist=False, supported=False))
            continue
        s = np.log(p) / sample_interval_s
        wn = float(abs(s))
        f_n = wn / (2 * np.pi)
        nyquist = bool(p.imag == 0 and p.real < 0)
        supported = not nyquist and (
            supported_band_hz is None or supported_band_hz[0] <= f_n <= supported_band_hz[1]
        )
        zeta = float(-s.real / wn) if wn > 0 else None
        modes.append(Mode(ModeKind.COMPLEX if p.imag > 0 else ModeKind.REAL, (float(p.real), float(p.imag)), f_n, zeta,
                          nyquist, bool(supported),
                          bool(p.imag > 0 and zeta is not None and zeta <= RESONANCE_MAX_DAMPING)))
    return sorted(modes, key=lambda m: m.natural_frequency_hz or 0.0)


def mark_doublets(modes: list[Mode], zeros: np.ndarray) -> list[Mode]:
    """Each complex mode with `cancelled` (a zero within DOUBLET_DISTANCE of the pole's distance
    to the unit circle: a pole–zero doublet, whose effect on the response is at most that
    fraction — the fit following a ripple of the data, not a resonance; docs/decisions/0013).
    A cancelled mode is not supported: it is no main mode and
    no pole a DCM may cancel."""
    z = np.asarray(zeros, dtype=complex)
    out = []
    for m in modes:
        m = replace(m, cancelled=False)
        if m.kind == ModeKind.COMPLEX and z.size and _nearly_cancelled(m.pole_z, z):
            m = replace(m, cancelled=True, supported=False)
        out.append(m)
    return out


def claimed(mode: Mode) -> bool:
    """Whether a mode is claimed: a resonance (ζ ≤ RESONANCE_MAX_DAMPING) the band supports, not
    cancelled by a zero (results written before `resonance` was kept: judged by its damping)."""
    zeta = mode.damping_ratio
    resonance = mode.resonance if mode.resonance is not None else zeta is not None and zeta <= RESONANCE_MAX_DAMPING
    return mode.kind == ModeKind.COMPLEX and mode.supported and resonance and not mode.cancelled


def main_mode(modes: list[Mode]) -> Mode | None:
    """The sensor's main mode: the lowest claimed resonance (`claimed`; None if there is none)."""
    pairs = [m for m in modes if claimed(m)]
    return min(pairs, key=lambda m: m.natural_frequency_hz or 0.0) if pairs else None


def resonance_above_hz(modes: list[Mode], band_hz: tuple[float, float] | None) -> float | None:
    """With no claimed mode but one beyond the band: the band's top (Hz), a lower bound of the
    resonance (it lies in a null of the excitation); else None."""
    if main_mode(modes) is not None or band_hz is None:
        return None
    top = band_hz[1]
    beyond = any(m.kind == ModeKind.COMPLEX and not m.cancelled and (m.natural_frequency_hz or 0.0) > top
                 for m in modes)
    return float(top) if beyond else None


def has_doublet(a: np.ndarray, b: np.ndarray, real: bool = False) -> bool:
    """Whether a complex pole pair of A(z) = 0 is nearly cancelled by a zero of B (`mark_doublets`'s
    test; the sample interval does not enter it, so any is given). `real`: a real pole nearly
    cancelled by a zero counts too (the same distance test): an order that adds such a pair to a
    lower one adds no feature the data determine — where the pair sits below the record's lowest
    bin, only how far apart its pole and zero lie, which sets the gain between DC and that bin
    (PTB's hybrids: order 2 plus a pair at 250–440 Hz, the lowest bin 606 Hz)."""
    if a.size < 2 or b.size < 2:
        return False
    poles, zeros = np.roots(a), np.roots(b)
    if any(m.cancelled for m in mark_doublets(modes_of(poles, 1.0), zeros)):
        return True
    single = poles[np.abs(poles.imag) <= 1e-12 * np.maximum(1.0, np.abs(poles))].real
    return real and any(_nearly_cancelled(complex(p), zeros) for p in single)


def _nearly_cancelled(pole: complex, zeros: np.ndarray) -> bool:
    """A zero lies within DOUBLET_DISTANCE of the pole's distance to the unit circle (a doublet)."""
    return float(np.min(np.abs(zeros - pole))) < DOUBLET_DISTANCE * (1.0 - abs(pole))
