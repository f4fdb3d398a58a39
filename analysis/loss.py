"""The least-squares loss ||g2||² of every model order from one factorisation (paper Eqs. 3–11).

The augmented information matrix of Eq. (3) has its columns ordered by lag,

    D = [u(k−N), −y(k−N), u(k−N+1), −y(k−N+1), …, u(k), −y(k)],   k = N … L−1,

with the coefficient of the last column fixed at 1 (θ = [b_N, a_N, …, b_0, 1]). For a
triangular factor R of D (D = QR), R[j, j]² is the squared residual of column j after
projection on the columns before it. Column 2n+1 is −y(t) with t = k−N+n, and the columns
before it are u(t−n), −y(t−n), …, u(t) — exactly the regressors of the order-n ARX model
A(d⁻¹)y = B(d⁻¹)u (b_0 … b_n, a_1 … a_n) on a time-shifted window of rows. So one
factorisation of the maximum-order matrix gives the loss of every order 0 … N, and the
leading block of R gives every order's coefficients by one triangular solve.

Fast path: the Gram matrix DᵀD from lagged dot products (4·(N+1) BLAS dot products over
the record plus O(N²) edge corrections, never forming D) and one Cholesky. Cholesky squares
the condition number, so when a pivot shows the loss is too close to rounding level the
accurate path is taken instead: a QR of D built in row blocks (memory stays bounded).
numpy/scipy have no routine for the nested losses of an augmented matrix, hence this module.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from hopkinson.analysis.errors import AnalysisError

# Below this ratio of residual to column energy a Cholesky pivot has lost too many digits
# (its relative error is ~ eps / ratio); the QR path is then used.
_CHOLESKY_MIN_PIVOT_RATIO = 1e-9
_QR_BLOCK_ROWS = 32_768
# OpenBLAS runs a dot product of more than 10 000 elements on several threads; on a machine
# whose cores are busy those threads wait for each other and one dot product can take 50×
# longer. Chunks below that size keep every dot product on the calling thread.
_DOT_CHUNK = 8192


def long_dot(a: np.ndarray, b: np.ndarray) -> float:
    """Σ a·b of two equally long 1-D float arrays, in single-threaded BLAS chunks."""
    n = a.size
    if n <= _DOT_CHUNK:
        return float(np.dot(a, b))
    total = 0.0
    for i in range(0, n, _DOT_CHUNK):
        total += float(np.dot(a[i : i + _DOT_CHUNK], b[i : i + _DOT_CHUNK]))
    return total


def _as_pair(u: np.ndarray, y: np.ndarray, max_order: int) -> tuple[np.ndarray, np.ndarray]:
    u = np.ascontiguousarray(u, dtype=float).ravel()
    y = np.ascontiguousarray(y, dtype=float).ravel()
    if u.size != y.size:
        raise AnalysisError(f"input and output have different lengths ({u.size} and {y.size})")
    if max_order < 0:
        raise AnalysisError(f"model order must be non-negative, got {max_order}")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise AnalysisError("input or output has a NaN or infinite value")
    need = 2 * (2 * max_order + 2)
    if u.size < need:
        raise AnalysisError(
            f"{u.size} samples are too few for order {max_order} "
            f"(need at least {need}: twice the {2 * max_order + 2} columns of the information matrix)"
        )
    return u, y


def lagged_cross_products(
    left: tuple[np.ndarray, np.ndarray], right: tuple[np.ndarray, np.ndarray], max_order: int
) -> np.ndarray:
    """ZᵀD for two augmented matrices built from equally long series, without forming them.

    Column 2i + p of the left matrix Z is left[p](r + i) for rows r = 0 … L−N−1 (i = 0 … N,
    two series per side); likewise D from `right`. Entry (2i+p, 2j+q) is a lagged dot
    product over a window of L − N samples: one full-length dot product per lag minus its
    head and tail (at most N terms each, done for all lags at once). 4·(2N+2) BLAS passes
    over the data in all, so the cost is nearly independent of N for long records.
    """
    n_max = max_order
    length = left[0].size
    rows = length - n_max
    size = 2 * n_max + 2
    out = np.empty((size, size))
    # All (s, m) with lag m = 0 … N and window start s = 0 … N − m.
    s_idx, m_idx = np.nonzero(np.add.outer(np.arange(n_max + 1), np.arange(n_max + 1)) <= n_max)
    same = {p: left[p] is right[p] for p in range(2)}
    for p in range(2):
        for q in range(2):
            full_forward: np.ndarray | None = None
            for forward in (True, False):
                # value(s, m) = Σ_{t=s}^{s+rows−1} xp(t)·xq(t+m): xp leads, xq lags by m.
                xp, xq = (left[p], right[q]) if forward else (right[q], left[p])
                if not forward and p == q and same[p] and full_forward is not None:
                    full = full_forward  # a series against itself: both directions agree
                else:
                    full = np.array([long_dot(xp[: length - m], xq[m:]) for m in range(n_max + 1)])
                full_forward = full
                lead = sliding_window_view(xq[: 2 * n_max + 1], n_max + 1)[:n_max]
                head = np.zeros((n_max + 1, n_max + 1))
                np.cumsum(xp[:n_max, None] * lead, axis=0, out=head[1:])
                trail = sliding_window_view(np.concatenate((xq[rows:], np.zeros(n_max + 1))), n_max + 1)[:n_max]
                tail = np.zeros((n_max + 1, n_max + 1))
                tail[:n_max] = np.cumsum((xp[rows:, None] * trail)[::-1], axis=0)[::-1]
                values = full[m_idx] - head[s_idx, m_idx] - tail[s_idx, m_idx]
                if forward:
                    out[2 * s_idx + p, 2 * (s_idx + m_idx) + q] = values
                else:
                    out[2 * (s_idx + m_idx) + p, 2 * s_idx + q] = values
    return out


def augmented_gram(u: np.ndarray, y: np.ndarray, max_order: int) -> np.ndarray:
    """DᵀD of the augmented information matrix (columns as in the module docstring)."""
    u, y = _as_pair(u, y, max_order)
    ny = -y
    return lagged_cross_products((u, ny), (u, ny), max_order)


def _triangular_factor(u: np.ndarray, y: np.ndarray, max_order: int, method: str) -> tuple[np.ndarray, str]:
    """Upper-triangular R with RᵀR = DᵀD, and the path that produced it."""
    if method not in ("auto", "cholesky", "qr"):
        raise AnalysisError(f"unknown factorisation method {method!r} (auto, cholesky or qr)")
    if method in ("auto", "cholesky"):
        gram = augmented_gram(u, y, max_order)
        try:
            r = np.linalg.cholesky(gram).T
            ratio = np.diag(r) ** 2 / np.maximum(np.diag(gram), np.finfo(float).tiny)
            if method == "cholesky" or np.min(ratio) > _CHOLESKY_MIN_PIVOT_RATIO:
                return r, "cholesky"
        except np.linalg.LinAlgError:
            if method == "cholesky":
                raise AnalysisError(
                    "the information matrix is numerically singular (noise-free or rank-deficient "
                    "data): use the QR path"
                ) from None
    return _blocked_qr_r(u, y, max_order), "qr"


def _blocked_qr_r(u: np.ndarray, y: np.ndarray, max_order: int) -> np.ndarray:
    """R of D = QR by QR of row blocks, stacking each block's R with the running one."""
    u, y = _as_pair(u, y, max_order)
    n_max = max_order
    rows = u.size - n_max
    size = 2 * n_max + 2
    r = np.zeros((0, size))
    for start in range(0, rows, _QR_BLOCK_ROWS):
        stop = min(rows, start + _QR_BLOCK_ROWS)
        block = np.empty((stop - start, size))
        for lag in range(n_max + 1):
            block[:, 2 * lag] = u[start + lag : stop + lag]
            block[:, 2 * lag + 1] = -y[start + lag : stop + lag]
        r = np.linalg.qr(np.vstack([r, block]), mode="r")[:size]
    # Signs of R's rows are arbitrary in QR; make the diagonal non-negative like Cholesky.
    signs = np.where(np.diag(r) < 0, -1.0, 1.0)
    return r * signs[:, None]


def arx_loss_by_order(u: np.ndarray, y: np.ndarray, max_order: int, method: str = "auto") -> np.ndarray:
    """Least-squares loss ||g2||² of the ARX models of order 1 … max_order (index 0 = order 1).

    One factorisation of the max-order augmented information matrix (Gram + Cholesky, or QR
    when the Gram matrix is too ill-conditioned; `method` forces "cholesky" or "qr"). Each
    order's loss is over L − max_order rows, so the losses are directly comparable.
    """
    r, _ = _triangular_factor(u, y, max_order, method)
    diag = np.diag(r)
    return diag[3 :: 2] ** 2


def arx_coefficients_by_order(
    u: np.ndarray, y: np.ndarray, max_order: int, method: str = "auto"
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(a, b) of the least-squares ARX model of every order 1 … max_order, same factorisation."""
    r, _ = _triangular_factor(u, y, max_order, method)
    models = []
    for n in range(1, max_order + 1):
        j = 2 * n + 1
        # R[:j,:j]·θ' = −R[:j, j] gives θ' = [b_n, a_n, …, a_1, b_0] (coefficient of column j is 1).
        theta = np.linalg.solve(r[:j, :j], -r[:j, j])
        b = theta[0::2][::-1]
        a = np.concatenate(([1.0], theta[1::2][::-1]))
        models.append((a, b))
    return models


def arx_fit(u: np.ndarray, y: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """Plain least-squares ARX model of `order`: (a with a[0] = 1, b = b_0 … b_n).

    The textbook reference (one numpy.linalg.lstsq on the explicit regression matrix), kept
    to show the bias of plain least squares and to check the fast path against.
    """
    u, y = _as_pair(u, y, order)
    n = order
    rows = u.size - n
    cols = [-y[n - i : n - i + rows] for i in range(1, n + 1)]
    cols += [u[n - i : n - i + rows] for i in range(n + 1)]
    phi = np.column_stack(cols)
    theta, *_ = np.linalg.lstsq(phi, y[n:], rcond=None)
    return np.concatenate(([1.0], theta[:n])), theta[n:]
