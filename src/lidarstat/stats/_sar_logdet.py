"""Spatial weights of the SAR model and the log-determinant ``log|I - rho W|`` of its
likelihood: exact from the eigenvalues of W or a sparse LU, or the Barry and Pace (1999)
series with stochastic traces for large n."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy import linalg as sla
from scipy.sparse.linalg import splu

from ..errors import InvalidParameterError

#: Largest n for which log|I - rho W| uses the eigenvalues of W (dense O(n^3) once).
EIG_MAX = 150
#: Largest n for which the sparse LU is used at every evaluation; above, the
#: Barry-Pace series.
LU_MAX = 50000
LOGDET_METHODS = ("auto", "eig", "lu", "series")


def weights_matrix(neighbor_lists_indptr, neighbor_lists_indices, n, *, row_standardize=True):
    """Sparse spatial weights from CSR adjacency (self-pairs dropped).

    Parameters
    ----------
    neighbor_lists_indptr, neighbor_lists_indices : ndarray
        CSR adjacency over ``n`` points (row i lists the neighbours of i).
    n : int
        Number of points.
    row_standardize : bool
        Divide each row by its sum (rows without neighbours stay zero).

    Returns
    -------
    scipy.sparse.csr_matrix
    """
    data = np.ones(neighbor_lists_indices.size)
    w = sp.csr_matrix((data, neighbor_lists_indices, neighbor_lists_indptr), shape=(n, n))
    w.setdiag(0.0)
    w.eliminate_zeros()
    w.sum_duplicates()
    w.data[:] = 1.0
    if row_standardize:
        rs = np.asarray(w.sum(axis=1)).ravel()
        with np.errstate(divide="ignore"):
            inv = np.where(rs > 0, 1.0 / rs, 0.0)
        w = sp.diags(inv) @ w
    return sp.csr_matrix(w)


class LogDet:
    """``rho -> log|I - rho W|``: exact (eigenvalues, sparse LU) or the Barry-Pace series.

    Parameters
    ----------
    W : sparse matrix (n, n)
        Spatial weights.
    method : {'auto', 'eig', 'lu', 'series'}
        ``eig``: exact from the eigenvalues of W; ``lu``: exact sparse LU at every
        evaluation (``sum log|U_ii|``); ``series``: see below. ``auto``: ``eig`` for
        n <= :data:`EIG_MAX`, ``lu`` for n <= :data:`LU_MAX`, ``series`` above.
    order, probes : int
        Terms and random probes of the series ``log|I - rho W| = -sum_k rho^k tr(W^k)/k``
        with ``tr(W^k)`` estimated by ``x'W^k x`` over Rademacher probes (Barry and Pace
        1999); ``tr(W)`` and ``tr(W^2)`` are exact.
    rng : Generator or int, optional
        Seed of the probes.
    """

    def __init__(self, W, method="auto", *, order=40, probes=30, rng=0):
        if method not in LOGDET_METHODS:
            raise InvalidParameterError(f"The 'method' parameter of LogDet must be one of "
                                        f"{LOGDET_METHODS}. Got {method!r} instead.")
        n = W.shape[0]
        if method == "auto":
            method = "eig" if n <= EIG_MAX else ("lu" if n <= LU_MAX else "series")
        self.method = method
        self.n = n
        self.W = sp.csc_matrix(W)
        self.evals = None
        if method == "eig":
            self.evals = _eigenvalues(W)
        elif method == "series":
            self.traces = _trace_powers(sp.csr_matrix(W), order, probes, rng)

    def bounds(self):
        """Open interval of rho for which I - rho W is non-singular (for real eigenvalues)."""
        if self.evals is not None and np.isrealobj(self.evals):
            lmin, lmax = float(self.evals.min()), float(self.evals.max())
            lo = 1.0 / lmin if lmin < 0 else -np.inf
            hi = 1.0 / lmax if lmax > 0 else np.inf
            return max(lo, -1.0), min(hi, 1.0)
        return -1.0, 1.0

    def _lu(self, rho):
        a = sp.identity(self.n, format="csc") - rho * self.W
        lu = splu(a)
        return float(np.sum(np.log(np.abs(lu.U.diagonal()))))

    def __call__(self, rho):
        if self.method == "eig":
            return float(np.sum(np.log(np.abs(1.0 - rho * self.evals))))
        if self.method == "lu":
            return self._lu(rho)
        k = np.arange(1, self.traces.size + 1)
        return float(-np.sum(rho ** k * self.traces / k))


def _eigenvalues(W):
    """Eigenvalues of W, through a symmetric similar matrix when W = D^-1 B with B symmetric."""
    W = sp.csr_matrix(W)
    B = W.copy()
    B.data[:] = 1.0
    if (B != B.T).nnz == 0:
        rs = np.asarray(W.sum(axis=1)).ravel()
        # W = D^-1 B (row-standardised symmetric binary) or W = B (binary symmetric)
        if np.allclose(W.data, 1.0):
            return sla.eigvalsh(W.toarray())
        d = np.asarray(B.sum(axis=1)).ravel()
        if np.allclose(rs[d > 0], 1.0) and np.allclose((sp.diags(d) @ W).data, 1.0):
            s = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 0.0)
            sym = (sp.diags(s) @ B @ sp.diags(s)).toarray()
            return sla.eigvalsh(sym)
    ev = sla.eigvals(W.toarray())
    return ev.real if np.allclose(ev.imag, 0.0) else ev


def _trace_powers(W, order, probes, rng):
    n = W.shape[0]
    gen = np.random.default_rng(rng)
    x = gen.choice([-1.0, 1.0], size=(n, probes))
    t = np.empty(order)
    v = x
    for k in range(order):
        v = W @ v
        t[k] = np.mean(np.sum(x * v, axis=0))
    t[0] = W.diagonal().sum()
    if order > 1:
        t[1] = W.multiply(W.T).sum()
    return t
