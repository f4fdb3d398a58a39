"""The data a frequency-domain fit works on: the two channels' DFT over the fitted bins with
their noise variances (`SpectralData`), and the points of a sine calibration fitted with the
shock (`SineTerms`). analysis.frequency_fit fits a model order to them."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class SineTerms:
    """Points of a sinusoidal calibration fitted with the shock (analysis.sine_joint): extra
    residuals of the same model, each weighed by its own uncertainty.

    At each point the residual is e = ln(κ·G(ω)·e^{−jωτ}·e^{jωτ_s}) − ln(S·e^{jφ}) (imaginary
    part wrapped to ±π): its real part the magnitude's relative error, its imaginary part the
    phase error (rad). κ (a free relative gain: the sine's level need not be in the shock's
    units) and τ_s (a free skew: the shock record's channel skew, which a sine calibration of
    the sensor alone does not have) are two extra parameters, so the sine constrains the
    model's shape only. The residuals are (Re e / σ_mag, Im e / σ_phase) × `weight`, where
    σ² = u² + s² (the stated standard uncertainty and the extra scatter s of analysis.sine_joint)
    and `weight` puts them on the scale of the shock's residuals (√ of the shock's V per degree
    of freedom, so each data set counts by its own uncertainty, model error included).
    """

    omega: np.ndarray  # rad/sample at the analysis rate
    log_target: np.ndarray  # ln S + jφ (S in any unit, φ in rad)
    sigma_mag: np.ndarray  # relative standard uncertainty of each magnitude (u² + s²)^½
    sigma_phase: np.ndarray  # rad
    weight: float = 1.0

    @property
    def size(self) -> int:
        return int(self.omega.size)

    def drawn(self, rng: np.random.Generator) -> SineTerms:
        """The points perturbed by their own uncertainty (a Monte Carlo draw)."""
        g = rng.standard_normal((2, self.size))
        return replace(self, log_target=self.log_target + self.sigma_mag * g[0] + 1j * self.sigma_phase * g[1])

    def start(self, g: np.ndarray) -> tuple[float, float]:
        """Weighted least-squares ln κ and τ_s for a model response g (with its delay) at the
        points: the starts of the two sine parameters."""
        e = self.log_target - np.log(g)
        w_m, w_p = self.sigma_mag ** -2, self.sigma_phase ** -2
        log_gain = float(np.sum(w_m * e.real) / np.sum(w_m))
        phase = (e.imag + np.pi) % (2.0 * np.pi) - np.pi
        skew = float(np.sum(w_p * self.omega * phase) / np.sum(w_p * self.omega ** 2))
        return log_gain, skew


@dataclass(frozen=True)
class SpectralData:
    """The two channels' DFT over the fitted bins, and their noise variances per bin.

    Per-bin form (`grouped` False): u, y are U_k, Y_k. Grouped form: suu, syy, syu are sums
    over each group of M bins (u, y None); `count` holds M. var_u, var_y are E|N_k|² of one
    bin in the group. `ramp` (per-bin only) is the DFT of the drift ramp, `transient` whether
    the transient term is fitted.
    """

    omega: np.ndarray  # rad/sample at each bin / group centre
    var_u: np.ndarray
    var_y: np.ndarray
    count: np.ndarray
    suu: np.ndarray
    syy: np.ndarray
    syu: np.ndarray
    u: np.ndarray | None = None
    y: np.ndarray | None = None
    ramp: np.ndarray | None = None
    transient: bool = False
    sine: SineTerms | None = None  # a sine calibration fitted with the shock (two residuals per point, like a bin)
    # Input terms (per-bin only; analysis.input_terms): the DFT of K signals made from the reference
    # (bins × K), whose fitted coefficients c correct the model's input, U + V·c; and each one's
    # prior weight w (c·w joins the residuals: a prior c ~ N(0, 1/w²); 0: none).
    inputs: np.ndarray | None = None
    input_prior: np.ndarray | None = None

    @property
    def input_count(self) -> int:
        return 0 if self.inputs is None else int(self.inputs.shape[1])

    @property
    def grouped(self) -> bool:
        return self.u is None

    @property
    def bins(self) -> int:
        """Number of DFT bins the cost sums over (a sine point, with its two residuals, counts as one)."""
        return int(np.sum(self.count)) + (self.sine.size if self.sine is not None else 0)

    @classmethod
    def per_bin(
        cls, omega: np.ndarray, u: np.ndarray, y: np.ndarray, var_u: np.ndarray, var_y: np.ndarray,
        ramp: np.ndarray | None = None, transient: bool = False, inputs: np.ndarray | None = None,
    ) -> SpectralData:
        return cls(omega, var_u, var_y, np.ones(omega.size), np.abs(u) ** 2, np.abs(y) ** 2, y * np.conj(u),
                   u, y, ramp, transient, inputs=inputs)

    @classmethod
    def grouped_from(
        cls, omega: np.ndarray, u: np.ndarray, y: np.ndarray, var_u: np.ndarray, var_y: np.ndarray, group: int
    ) -> SpectralData:
        """Sufficient statistics of groups of `group` adjacent bins (the last group may be shorter)."""
        edges = np.arange(0, omega.size, group)
        count = np.diff(np.append(edges, omega.size)).astype(float)
        suu = np.add.reduceat(np.abs(u) ** 2, edges)
        syy = np.add.reduceat(np.abs(y) ** 2, edges)
        syu = np.add.reduceat(y * np.conj(u), edges)
        centre = np.add.reduceat(omega, edges) / count
        return cls(centre, np.add.reduceat(var_u, edges) / count, np.add.reduceat(var_y, edges) / count, count,
                   suu, syy, syu)

    def in_layout(self, per_bin: np.ndarray) -> np.ndarray:
        """Values given per DFT bin (a noise variance) in this data's layout: as they are per bin,
        averaged over each group when grouped (as `grouped_from` averages the variances)."""
        if not self.grouped:
            return per_bin
        edges = np.concatenate(([0], np.cumsum(self.count[:-1]))).astype(int)
        return np.add.reduceat(per_bin, edges) / self.count

    def below(self, omega_max: float) -> SpectralData:
        """The same data over the bins (or groups) at or below `omega_max` only (rad/sample); a
        sine calibration fitted with the shock keeps all its points."""
        keep = self.omega <= omega_max

        def cut(x: np.ndarray | None) -> np.ndarray | None:
            return None if x is None else x[keep]

        return replace(self, omega=self.omega[keep], var_u=self.var_u[keep], var_y=self.var_y[keep],
                       count=self.count[keep], suu=self.suu[keep], syy=self.syy[keep], syu=self.syu[keep],
                       u=cut(self.u), y=cut(self.y), ramp=cut(self.ramp), inputs=cut(self.inputs))

    def perturbed(self, u: np.ndarray, y: np.ndarray, group: int) -> SpectralData:
        """The same bins and noise with other channel spectra (a Monte Carlo draw)."""
        if self.grouped:
            edges = np.arange(0, u.size, group)
            return replace(self, suu=np.add.reduceat(np.abs(u) ** 2, edges),
                           syy=np.add.reduceat(np.abs(y) ** 2, edges),
                           syu=np.add.reduceat(y * np.conj(u), edges))
        return replace(self, u=u, y=y, suu=np.abs(u) ** 2, syy=np.abs(y) ** 2, syu=y * np.conj(u))
