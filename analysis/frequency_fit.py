"""Errors-in-variables output-error fit of one model order, in the frequency domain, weighted
to the band the excitation supports.

The model relates the DFTs of the two channels over a window of L samples,

    Y_k = e^{−jω_k τ} · B(z_k⁻¹)/A(z_k⁻¹) · U_k  [+ I(z_k⁻¹)/A(z_k⁻¹) + c·R_k] + noise,

with z_k = e^{jω_k}, a fractional input delay τ ≥ 0 (samples), and, for a record that ends
before the response has died away, the transient term I/A (deg I = n − 1: the state left at
the window's end) and a drift c·R_k (R the DFT of a ramp). Both channels are noisy: with
noise variances σ_U²(k), σ_Y²(k) per bin (analysis.noise) the estimate minimises

    V(θ) = Σ_k |Y_k − G_k U_k − …|² / (σ_Y²(k) + |G_k|²·σ_U²(k))

over the bins of the supported band: the sample maximum-likelihood estimator of Pintelon and
Schoukens (System Identification: A Frequency Domain Approach, 2nd ed., §10.3, §12), which
stays consistent when the reference is noisy (errors-in-variables), where plain output error
is biased towards a smaller gain. At the true model each bin adds 1 on average, so V ≈ K and
nested orders can be compared by an F test (analysis.identify).

Long records (more bins than the band needs) are reduced to groups of M adjacent bins, whose
sufficient statistics S_uu, S_yy, S_yu give the same cost exactly when G is constant across
the group (the groups are far narrower than any resonance the band can resolve).

Starting values: Sanathanan–Koerner iterations (the linearised cost re-weighted by the last
1/|A|², the frequency-domain Steiglitz–McBride) from a linear least-squares fit; then
Levenberg–Marquardt (analysis.numerics, Marquardt's scaling) on V with its analytic Jacobian.
Unstable trial steps are rejected. numpy/scipy have no errors-in-variables transfer-function
estimator, hence this module. The fitted model of an order, and the tests on it (stability, the
damping floor): analysis.order_fit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hopkinson.analysis.numerics import levenberg_marquardt
from hopkinson.analysis.order_fit import OrderFit, damping_floored, is_stable, response, stabilised
from hopkinson.analysis.spectral_data import SpectralData
from hopkinson.analysis.structure import DelayMode

CAUSAL_START = 1e-4  # samples: a causal delay starts at least this far from zero
RCOND = 1e-4  # singular values below this × the largest are ignored by the quick refits (the delay–zeros valley)
SK_ITERATIONS = 6


def predicted_bins(fit: OrderFit, data: SpectralData, omega: np.ndarray, u_bins: np.ndarray,
                   g: np.ndarray | None = None) -> np.ndarray:
    """The model's response spectrum at the fitted bins (before any grouping): e^{−jωτ}·B/A·U,
    plus the transient and drift terms where the per-bin fit has them (`g`: `response(fit, omega)`
    where the caller has it already)."""
    if not data.grouped:
        problem = OrderProblem.for_fit(data, fit, fit.delay)
        theta = problem.pack(replace(fit, transient=fit.transient if fit.transient.size else np.zeros(0)))
        return data.y - problem._error(problem._pieces(theta))
    return (response(fit, omega) if g is None else g) * u_bins


_POWERS: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
_POWERS_KEPT = 32


def z_powers(omega: np.ndarray, order: int) -> np.ndarray:
    """z_k^{−i} = e^{−jω_k i}, i = 0…order (bins × order+1). The Monte Carlo draws build a problem
    per draw on the same bins (`SpectralData.perturbed` keeps the ω array): the last few tables
    are kept, keyed by the array itself (held, so its id is not reused) and the order."""
    key = (id(omega), order)
    kept = _POWERS.get(key)
    if kept is not None and kept[0] is omega:
        return kept[1]
    powers = np.exp(-1j * np.outer(omega, np.arange(order + 1)))
    powers.flags.writeable = False
    if len(_POWERS) >= _POWERS_KEPT:
        _POWERS.pop(next(iter(_POWERS), None), None)
    _POWERS[key] = (omega, powers)
    return powers


class OrderProblem:
    """V(θ) of one order on one SpectralData: residuals, Jacobian, starts and the solve.

    delay: "causal" (0 ≤ τ ≤ max_delay, as τ = max_delay·sin²t: the parameter is t), "free"
    (τ of either sign: only to test whether the response leads the reference) or a number (τ
    fixed there).
    numerator: B's fixed shape (B = g·shape: one parameter g; `all_pole_numerator`); None: B free
    (n + 1 parameters).
    """

    @classmethod
    def for_fit(cls, data: SpectralData, fit: OrderFit, delay: DelayMode | float = DelayMode.CAUSAL,
                max_delay: float = 32.0) -> OrderProblem:
        """The problem `fit` solves (its order and B's structure) on `data`."""
        return cls(data, fit.order, delay, max_delay, numerator=fit.numerator)

    def __init__(self, data: SpectralData, order: int, delay: DelayMode | float = DelayMode.CAUSAL, max_delay: float = 32.0,
                 numerator: np.ndarray | None = None) -> None:
        self.max_delay = float(max_delay)
        self.data = data
        self.n = order
        if isinstance(delay, str) and delay not in DelayMode.__members__.values():
            raise ValueError(f"unknown delay mode {delay!r}")
        self.delay_mode = DelayMode(delay) if isinstance(delay, str) else DelayMode.FIXED
        self.fixed_delay = None if isinstance(delay, str) else float(delay)
        self.powers = z_powers(data.omega, order)  # z_k^{-i}
        self.numerator = None if numerator is None else np.asarray(numerator, dtype=float)
        if self.numerator is not None and self.numerator.size != order + 1:
            raise ValueError(f"a numerator shape of order {order} has {order + 1} coefficients")
        # ∂b/∂(B's parameters): the identity (B free) or the shape's column (B = g·shape)
        self.b_map = np.eye(order + 1) if self.numerator is None else self.numerator[:, None]
        self.nb = self.b_map.shape[1]
        self.k_delay = order + self.nb  # index of the delay parameter (when it is free)
        self.n_transient = order if (data.transient and not data.grouped) else 0
        self.drift = data.ramp is not None and not data.grouped
        self.n_inputs = 0 if data.grouped else data.input_count
        prior = data.input_prior if self.n_inputs and data.input_prior is not None else np.zeros(self.n_inputs)
        self.prior_columns = np.flatnonzero(prior > 0)
        self.prior_weights = prior[self.prior_columns]
        self.n_prior = int(self.prior_columns.size)  # residual rows of the input terms' prior, after the bins'
        self.sine = data.sine
        self.size = (order + self.nb + (self.fixed_delay is None) + self.n_transient + int(self.drift)
                     + self.n_inputs)
        if self.sine is not None:  # ln κ and τ_s of SineTerms, last
            self.sine_powers = np.exp(-1j * np.outer(self.sine.omega, np.arange(order + 1)))
            self.size += 2
        self._prior_rows = np.zeros((self.n_prior, self.size))  # the prior's Jacobian rows (constant)
        self._prior_rows[np.arange(self.n_prior), self._k_inputs + self.prior_columns] = self.prior_weights
        self._rejected: np.ndarray | None = None
        self._last_pieces: tuple[bytes, dict[str, np.ndarray | float]] | None = None
        self._last_residuals: list[tuple[bytes, np.ndarray]] = []
        self._minus_j_omega = -1j * data.omega  # θ-independent, as the prior's rows

    # -- parameter vector ------------------------------------------------------------------
    def pack(self, fit: OrderFit) -> np.ndarray:
        b = fit.b if self.numerator is None else [float(fit.b @ self.numerator) / float(self.numerator @ self.numerator)]
        parts = [fit.a[1:], b]
        if self.delay_mode == DelayMode.CAUSAL:
            # τ = τmax·sin²t: a start on a bound would have no gradient in t, so it starts just off it.
            x = min(max(fit.delay, CAUSAL_START), self.max_delay - CAUSAL_START) / self.max_delay
            parts.append([math.asin(math.sqrt(x))])
        elif self.delay_mode == DelayMode.FREE:
            parts.append([fit.delay])
        if self.n_transient:
            t = fit.transient if fit.transient.size == self.n_transient else np.zeros(self.n_transient)
            parts.append(t)
        if self.drift:
            parts.append([fit.drift])
        if self.n_inputs:
            parts.append(fit.inputs if fit.inputs.size == self.n_inputs else np.zeros(self.n_inputs))
        if self.sine is not None:
            if math.isfinite(fit.sine_gain):
                parts.append([fit.sine_gain, fit.sine_skew])
            else:  # a start without them: their best values for this transfer function
                g = (self.sine_powers[:, : fit.b.size] @ fit.b) / (self.sine_powers[:, : fit.a.size] @ fit.a)
                parts.append(self.sine.start(g * np.exp(-1j * self.sine.omega * fit.delay)))
        return np.concatenate([np.asarray(p, dtype=float) for p in parts])

    def unpack(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, float]:
        n = self.n
        a = np.concatenate(([1.0], theta[:n]))
        k = self.k_delay
        b = self.b_map @ theta[n:k]
        if self.delay_mode == DelayMode.FIXED:
            tau = float(self.fixed_delay)
        else:
            tau = self.max_delay * math.sin(theta[k]) ** 2 if self.delay_mode == DelayMode.CAUSAL else float(theta[k])
            k += 1
        transient = theta[k : k + self.n_transient]
        k += self.n_transient
        drift = float(theta[k]) if self.drift else 0.0
        return a, b, tau, transient, drift

    @property
    def _k_inputs(self) -> int:
        """Index of the first input term's coefficient in θ."""
        return self.k_delay + (self.fixed_delay is None) + self.n_transient + int(self.drift)

    def input_coefficients(self, theta: np.ndarray) -> np.ndarray:
        """The input terms' coefficients c in θ (empty without input terms)."""
        k = self._k_inputs
        return np.array(theta[k : k + self.n_inputs], dtype=float)

    def fit_of(self, theta: np.ndarray, cost: float, evaluations: int, converged: bool) -> OrderFit:
        if self.numerator is not None:  # the all-pole structure's estimator floors the damping beyond the band
            floored = damping_floored(np.concatenate(([1.0], theta[: self.n])), float(np.max(self.data.omega)))
            if floored is not None:
                theta = np.concatenate((floored[1:], theta[self.n :]))
                cost = self.cost(theta)
        a, b, tau, transient, drift = self.unpack(theta)
        fit = OrderFit(a, b, tau, np.array(transient), drift, cost, self.size, evaluations, converged,
                       self.fixed_delay is not None, numerator=self.numerator, inputs=self.input_coefficients(theta))
        if self.sine is None:
            return fit
        r = self._sine_residual(theta)
        return replace(fit, sine_gain=float(theta[-2]), sine_skew=float(theta[-1]), sine_cost=0.5 * float(r @ r))

    # -- model pieces ------------------------------------------------------------------------
    def _pieces(self, theta: np.ndarray) -> dict[str, np.ndarray | float]:
        """A, B, G, the delay, the weights' s² and the corrected input at θ; the last θ's are
        kept (the Jacobian is asked for at the point whose residual was just evaluated)."""
        key = theta.tobytes()
        if self._last_pieces is not None and self._last_pieces[0] == key:
            return self._last_pieces[1]
        pieces = self._evaluate_pieces(theta)
        self._last_pieces = (key, pieces)
        return pieces

    def _evaluate_pieces(self, theta: np.ndarray) -> dict[str, np.ndarray | float]:
        a, b, tau, transient, drift = self.unpack(theta)
        d = self.data
        pw = self.powers
        big_a = pw @ a
        big_b = pw @ b
        g = big_b / big_a
        delay = np.exp(self._minus_j_omega * tau)
        s2 = d.var_y + np.abs(g) ** 2 * d.var_u
        u = d.u
        if self.n_inputs:  # the corrected input U + V·c
            u = d.u + d.inputs @ self.input_coefficients(theta)
        return {"A": big_a, "B": big_b, "G": g, "D": delay, "s2": s2, "sigma": np.sqrt(s2), "tau": tau,
                "transient": transient, "drift": drift, "U": u}

    def residual(self, theta: np.ndarray) -> np.ndarray:
        """The shock's residuals, then the sine points' (SineTerms) when there are any. The last
        two θ's are kept (a solve evaluates its start, and its end, twice). Not to be written to."""
        key = theta.tobytes()
        for kept, r in self._last_residuals:
            if kept == key:
                return r
        r = self._shock_residual(theta)
        if self.sine is not None and r is not self._rejected:
            r = np.concatenate((r, self._sine_residual(theta)))
        self._last_residuals = [(key, r), *self._last_residuals[:1]]
        return r

    def _sine_error(self, theta: np.ndarray) -> np.ndarray:
        """e of SineTerms at each sine point (imaginary part wrapped to ±π)."""
        assert self.sine is not None
        a, b, tau, _, _ = self.unpack(theta)
        w = self.sine.omega
        e = (np.log(self.sine_powers @ b) - np.log(self.sine_powers @ a) - 1j * w * tau + theta[-2]
             + 1j * w * theta[-1] - self.sine.log_target)
        return e.real + 1j * ((e.imag + np.pi) % (2.0 * np.pi) - np.pi)

    def _sine_residual(self, theta: np.ndarray) -> np.ndarray:
        assert self.sine is not None
        e = self._sine_error(theta)
        return self.sine.weight * np.concatenate((e.real / self.sine.sigma_mag, e.imag / self.sine.sigma_phase))

    def _sine_jacobian(self, theta: np.ndarray) -> np.ndarray:
        assert self.sine is not None
        n = self.n
        a, b, _, _, _ = self.unpack(theta)
        pw = self.sine_powers
        w = self.sine.omega
        de = np.zeros((w.size, self.size), dtype=complex)
        de[:, :n] = -pw[:, 1:] / (pw @ a)[:, None]
        de[:, n : self.k_delay] = (pw / (pw @ b)[:, None]) @ self.b_map
        if self.fixed_delay is None:
            de[:, self.k_delay] = -1j * w * self._dtau(theta)
        de[:, -2] = 1.0
        de[:, -1] = 1j * w
        s = self.sine
        return s.weight * np.vstack((de.real / s.sigma_mag[:, None], de.imag / s.sigma_phase[:, None]))

    def _shock_residual(self, theta: np.ndarray) -> np.ndarray:
        a = np.concatenate(([1.0], theta[: self.n]))
        if not is_stable(a):
            return self._reject()
        p = self._pieces(theta)
        d = self.data
        sigma = p["sigma"]
        if d.grouped:
            gd = p["D"] * p["G"]
            ghat = d.syu / d.suu
            c = np.maximum(d.syy - np.abs(d.syu) ** 2 / d.suu, 0.0)
            r1 = math.sqrt(2.0) * np.sqrt(d.suu) * (gd - ghat) / sigma
            r2 = np.sqrt(2.0 * c) / sigma
            return np.concatenate((r1.real, r1.imag, r2))
        r = math.sqrt(2.0) * self._error(p) / sigma
        m = r.size
        out = np.empty(2 * m + self.n_prior)
        out[:m] = r.real
        out[m : 2 * m] = r.imag
        if self.n_prior:
            out[2 * m :] = self.prior_weights * self.input_coefficients(theta)[self.prior_columns]
        return out

    def _error(self, p: dict) -> np.ndarray:
        """Y − the model's prediction at the pieces `p` (kept in them: the Jacobian at the same θ reads it)."""
        if "error" not in p:
            p["error"] = self._prediction_error(p)
        return p["error"]

    def _prediction_error(self, p: dict) -> np.ndarray:
        d = self.data
        pred = p["D"] * p["G"] * p["U"]
        if self.n_transient:
            pred = pred + (self.powers[:, : self.n_transient] @ p["transient"]) / p["A"]
        if self.drift:
            pred = pred + p["drift"] * d.ramp
        return d.y - pred

    def _reject(self) -> np.ndarray:
        if self._rejected is None:
            m = 3 * self.data.omega.size if self.data.grouped else 2 * self.data.omega.size + self.n_prior
            self._rejected = np.full(m + 2 * (self.sine.size if self.sine is not None else 0), 1e8)
        return self._rejected

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        jac = self._shock_jacobian(theta)
        return jac if self.sine is None else np.vstack((jac, self._sine_jacobian(theta)))

    def _shock_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """∂r/∂θ of the shock's residuals. G depends on A's and B's parameters only (the first
        `k_delay` columns): the weights' derivative is formed on those columns alone."""
        p = self._pieces(theta)
        d = self.data
        n, k = self.n, self.k_delay
        big_a, g, delay = p["A"], p["G"], p["D"]
        s2, sigma = p["s2"], p["sigma"]
        e_over_a = self.powers / big_a[:, None]  # z^{-i}/A
        dg = np.empty((d.omega.size, k), dtype=complex)  # ∂G/∂(A's and B's parameters)
        dg[:, :n] = -g[:, None] * e_over_a[:, 1 : n + 1]
        dg[:, n:] = e_over_a if self.numerator is None else e_over_a @ self.b_map
        ds2 = 2.0 * d.var_u[:, None] * np.real(np.conj(g)[:, None] * dg)
        if d.grouped:
            return self._grouped_jacobian(theta, p, dg, ds2)
        err = self._error(p)
        u = p["U"]
        m = d.omega.size
        dpred = np.empty((m, self.size), dtype=complex)  # ∂(the prediction)/∂θ
        dpred[:, :k] = delay[:, None] * dg * u[:, None]
        if self.n_transient:
            trans = (self.powers[:, : self.n_transient] @ p["transient"]) / big_a
            dpred[:, :n] -= trans[:, None] * e_over_a[:, 1 : n + 1]
        j = k
        if self.fixed_delay is None:
            dpred[:, j] = self._minus_j_omega * delay * g * u * self._dtau(theta)
            j += 1
        if self.n_transient:
            dpred[:, j : j + self.n_transient] = e_over_a[:, : self.n_transient]
            j += self.n_transient
        if self.drift:
            dpred[:, j] = d.ramp
            j += 1
        if self.n_inputs:
            dpred[:, j : j + self.n_inputs] = (delay * g)[:, None] * d.inputs
            j += self.n_inputs
        dpred[:, j:] = 0.0  # the sine terms' parameters (SineTerms) do not enter the shock's rows
        # J = √2·(−∂pred/σ − err/(2s²σ)·∂s²) (∂s² on the first k columns only), real parts over
        # imaginary parts, in real arithmetic with the complex expression's values: NumPy divides a
        # complex number by a real σ as (x·(1/σ), y·(1/σ)) and multiplies it by a real one part by
        # part, and √2·(−a − b) = −√2·(a + b) exactly.
        out = np.empty((2 * m + self.n_prior, self.size))
        inv_sigma = (1.0 / sigma)[:, None]
        w = err * (1.0 / (2.0 * s2 * sigma))  # err/(2s²σ)
        for half, part, w_part in ((out[:m], dpred.real, w.real), (out[m : 2 * m], dpred.imag, w.imag)):
            np.multiply(part, inv_sigma, out=half)
            half[:, :k] += w_part[:, None] * ds2
            half *= -math.sqrt(2.0)
        out[2 * m :] = self._prior_rows
        return out

    def _grouped_jacobian(self, theta: np.ndarray, p: dict, dg: np.ndarray, ds2: np.ndarray) -> np.ndarray:
        """∂r/∂θ on grouped bins (`_shock_jacobian`'s ∂G and ∂s² on A's and B's parameters given)."""
        d = self.data
        k = self.k_delay
        g, delay, s2, sigma = p["G"], p["D"], p["s2"], p["sigma"]
        gd = delay * g
        dgd = np.zeros((d.omega.size, self.size), dtype=complex)
        dgd[:, :k] = delay[:, None] * dg
        if self.fixed_delay is None:
            dgd[:, k] = self._minus_j_omega * gd * self._dtau(theta)
        full_ds2 = np.zeros((d.omega.size, self.size))
        full_ds2[:, :k] = ds2
        ghat = d.syu / d.suu
        c = np.maximum(d.syy - np.abs(d.syu) ** 2 / d.suu, 0.0)
        w = math.sqrt(2.0) * np.sqrt(d.suu)
        j1 = w[:, None] * (dgd / sigma[:, None] - ((gd - ghat) / (2.0 * s2 * sigma))[:, None] * full_ds2)
        j2 = -(np.sqrt(2.0 * c) / (2.0 * s2 * sigma))[:, None] * full_ds2
        return np.vstack((j1.real, j1.imag, j2))

    def _dtau(self, theta: np.ndarray) -> float:
        """∂τ/∂(delay parameter): τmax·sin 2t for τ = τmax·sin²t, else 1."""
        return self.max_delay * math.sin(2.0 * theta[self.k_delay]) if self.delay_mode == DelayMode.CAUSAL else 1.0

    def cost(self, theta: np.ndarray) -> float:
        r = self.residual(theta)
        return 0.5 * float(r @ r)

    # -- solving -----------------------------------------------------------------------------
    def solve(self, start: OrderFit, max_evaluations: int = 60, tolerance: float = 1e-8,
              stop_at_delay: Callable[[float], bool] | None = None) -> OrderFit:
        """Levenberg–Marquardt from `start`; never returns a higher cost than the start's
        (`start.cost`, when it was evaluated on these data, else its cost here).
        `stop_at_delay(τ)` true after a step ends the search there."""
        theta0 = self.pack(start)
        r0 = self.residual(theta0)
        cost0 = 0.5 * float(r0 @ r0)
        # (a start fitted without the sine terms has a cost of other data)
        same_data = self.sine is None or math.isfinite(start.sine_gain)
        if math.isfinite(start.cost) and start.cost < cost0 and start.a.size == self.n + 1 and same_data:
            fallback = replace(start, parameters=self.size, evaluations=0, converged=False)
        else:
            fallback = self.fit_of(theta0, cost0, 0, False)
        if self.residual_size() < self.size:
            return fallback
        try:
            stop = None if stop_at_delay is None else (lambda theta: stop_at_delay(self.unpack(theta)[2]))
            result = levenberg_marquardt(self.residual, self.jacobian, theta0, max_evaluations, tolerance, stop, r0)
        except (ValueError, np.linalg.LinAlgError):
            return fallback
        cost = result.cost  # ½‖r‖² of the residual at result.x, as the search evaluated it
        if not (np.isfinite(cost) and cost <= fallback.cost):
            return replace(fallback, evaluations=result.evaluations)
        return self.fit_of(result.x, cost, result.evaluations, result.converged)

    def residual_size(self) -> int:
        """Rows of the residual: the bins' (and the input terms' prior's), then the sine points'."""
        return ((3 if self.data.grouped else 2) * self.data.omega.size + self.n_prior
                + 2 * (self.sine.size if self.sine else 0))

    def linear_start(self, delay: float, iterations: int = SK_ITERATIONS, inputs: np.ndarray | None = None
                     ) -> OrderFit:
        """Sanathanan–Koerner start at a fixed delay (no drift), poles reflected inside; the input
        terms held at `inputs` (None: zero)."""
        d = self.data
        c = np.zeros(self.n_inputs) if inputs is None or inputs.size != self.n_inputs else np.asarray(inputs)
        u = d.u if not self.n_inputs else d.u + d.inputs @ c
        n = self.n
        dl = np.exp(-1j * d.omega * delay)
        pw = self.powers
        a = np.concatenate(([1.0], np.zeros(n)))
        b = np.zeros(n + 1)
        transient = np.zeros(self.n_transient)
        raw_unstable = False
        for _ in range(iterations):
            big_a = pw @ a
            g = (pw @ b) / big_a
            weight = 1.0 / (np.abs(big_a) * np.sqrt(d.var_y + np.abs(g) ** 2 * d.var_u))
            rows, rhs = self._linear_rows(dl, weight, u)
            try:
                x, *_ = np.linalg.lstsq(np.vstack((rows.real, rows.imag)), np.concatenate((rhs.real, rhs.imag)),
                                        rcond=None)
            except (np.linalg.LinAlgError, ValueError):
                break
            raw = np.concatenate(([1.0], x[:n]))
            raw_unstable = not is_stable(raw)
            a = stabilised(raw)
            b = self.b_map @ x[n : self.k_delay]
            transient = x[self.k_delay :]
            if not np.all(np.isfinite(a)) or not np.all(np.isfinite(b)):
                a, b = np.concatenate(([1.0], np.zeros(n))), np.zeros(n + 1)
                break
        fit = OrderFit(a, b, delay, transient, 0.0, float("nan"), self.size, 0, False, self.fixed_delay is not None,
                       raw_unstable, numerator=self.numerator, inputs=c)
        return replace(fit, cost=self.cost(self.pack(fit)))

    def _linear_rows(self, dl: np.ndarray, weight: np.ndarray, u: np.ndarray | None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Rows of the linearised cost Σ w²|A·Y − D·B·U − I|² in x = (a_1..a_n, b_0..b_n, i)."""
        d = self.data
        n = self.n
        pw = self.powers
        if d.grouped:
            # Σ_k |A·Y_k − D·B·U_k|² = ‖R·(A, −D·B)‖² with RᴴR = [[S_yy, S_yu], [S_yu*, S_uu]].
            r11 = np.sqrt(np.maximum(d.syy, 1e-300))
            r12 = d.syu / r11
            r22 = np.sqrt(np.maximum(d.suu - np.abs(d.syu) ** 2 / d.syy, 0.0))
            w = weight[:, None]
            pb = pw @ self.b_map
            row1 = np.hstack((w * r11[:, None] * pw[:, 1:], -w * (r12 * dl)[:, None] * pb))
            row2 = np.hstack((np.zeros((d.omega.size, n), dtype=complex), -w * (r22 * dl)[:, None] * pb))
            rows = np.vstack((row1, row2))
            rhs = np.concatenate((-weight * r11, np.zeros(d.omega.size)))
            return rows, rhs
        w = weight[:, None]
        parts = [w * d.y[:, None] * pw[:, 1:], -w * (dl * u)[:, None] * (pw @ self.b_map)]
        if self.n_transient:
            parts.append(-w * pw[:, : self.n_transient])
        return np.hstack(parts), -weight * d.y
