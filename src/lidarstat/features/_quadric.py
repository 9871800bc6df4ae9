"""Weighted local quadric (second-order Taylor) fits: the public wrapper over the kernel."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from .._shared._choices import Frame
from .._shared._jit import dynamic_schedule
from .._shared.validation import check_option, check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import Neighborhoods
from . import _frame_kernels as _fk
from . import _quadric_cells as _qc
from . import _quadric_kernels as _k

FRAMES = {"z": _fk.FRAME_Z, "auto": _fk.FRAME_AUTO, "pca": _fk.FRAME_PCA}
COVARIANCES = {"paper": _k.COV_PAPER, "sandwich": _k.COV_SANDWICH}


class FitStatus(IntEnum):
    """Why a point has (or has no) local model; written to the ``status`` field."""

    OK = 0
    TOO_FEW_NEIGHBORS = 1
    DEGENERATE = 2  # singular normal matrix: collinear points, duplicates
    MODEL_REJECTED = 3  # fitted, but the chi-square test rejects the quadric


@dataclass(frozen=True)
class QuadricFit:
    """Per-point weighted quadric fits.

    Attributes
    ----------
    status : (N,) ndarray of uint8
        :class:`FitStatus` code (OK, TOO_FEW_NEIGHBORS or DEGENERATE).
    neighbors : (N,) ndarray of int32
        Neighbours with positive weight, p.
    beta : (N, 6) ndarray
        ``[a0, a1, a2, a3, a4, a5]`` of eq. 1 in the local frame (NaN where not fitted).
    cofactor : (N, 6, 6) ndarray
        Cofactor matrix of `beta`: ``(X'WX)^-1`` (``covariance='paper'``) or the
        sandwich ``(X'WX)^-1 X'W^2X (X'WX)^-1`` (``'sandwich'``); times sigma^2 it is the
        covariance of `beta` under independent noise of variance sigma^2.
    frame : (N, 3, 3) ndarray
        Rows e1, e2, n of the local frame in file coordinates; n is the height axis.
    q : (N,) ndarray
        Weighted residual sum of squares v'Wv.
    sum_w, trace_b, trace_b2 : (N,) ndarray
        Sum of weights, tr(B) and tr(B^2) for ``B = W - W X (X'WX)^-1 X' W``.
    bandwidth : float or None
        Kernel radius b (None: per-point farthest neighbour, for kNN).
    covariance : str
        Which cofactor `cofactor` holds.
    """

    status: np.ndarray
    neighbors: np.ndarray
    beta: np.ndarray
    cofactor: np.ndarray
    frame: np.ndarray
    q: np.ndarray
    sum_w: np.ndarray
    trace_b: np.ndarray
    trace_b2: np.ndarray
    bandwidth: float | None
    covariance: str

    def __len__(self) -> int:
        return self.status.size

    @property
    def normal(self) -> np.ndarray:
        """Unit surface normals (N, 3) in file coordinates, oriented along +n of the frame."""
        a1, a2 = self.beta[:, 1], self.beta[:, 2]
        nl = np.stack([-a1, -a2, np.ones_like(a1)], axis=1)
        nl /= np.linalg.norm(nl, axis=1, keepdims=True)
        return np.einsum("nij,ni->nj", self.frame, nl)


def _allocate(m):
    return dict(
        status=np.zeros(m, np.uint8), npts=np.zeros(m, np.int32), beta=np.empty((m, 6)),
        cof=np.empty((m, 6, 6)), frames=np.empty((m, 3, 3)), stats=np.empty((m, 4)),
    )


def _outs(out):
    """The output tuple of the quadric kernels (``_quadric_kernels._quadric_point``)."""
    return (out["status"], out["npts"], out["beta"], out["cof"], out["frames"], out["stats"])


def _run_kernel(pts, query, indptr, idx, dist, *, bandwidth, frame, sensor, min_neighbors,
                covariance):
    """Fit one block; `pts` local coordinates, `query` positions into `pts`."""
    m = query.size
    out = _allocate(m)
    has_sensor = sensor is not None
    sensor_arr = np.zeros(3) if sensor is None else np.asarray(sensor, dtype=np.float64)
    # the neighbour-index dtype of lidarstat.neighbors (int32 below 2**31 points), also for
    # indices built here (np.flatnonzero): one compiled variant of the kernel
    idx = np.ascontiguousarray(idx, dtype=np.int32 if pts.shape[0] < 2**31 else np.int64)
    _k.fit_quadrics_block(
        pts, np.ascontiguousarray(query, dtype=np.int64), indptr, idx, dist,
        (-1.0 if bandwidth is None else float(bandwidth), FRAMES[Frame(frame).value], sensor_arr, has_sensor,
         int(min_neighbors), COVARIANCES[covariance]), _outs(out),
    )
    return _mark_unfitted(out)


def _mark_unfitted(out):
    bad = out["status"] != _k.OK
    out["cof"][bad] = np.nan
    out["frames"][bad & (out["status"] == _k.TOO_FEW)] = np.nan
    return out


def _run_cells(index, c0, c1, *, bandwidth, frame, sensor, min_neighbors, covariance,
               active=None, buffers=None):
    """Fused neighbour search + fit of the points of cells c0..c1-1 of a 3-D CellIndex.

    `active` (uint8 per sorted position, default all) restricts the fit to some points.
    `buffers` (from :func:`_allocate`, at least as many rows as the block) receive the
    outputs, which are then views of them, valid until the next call with the same
    buffers: a caller that fits block after block reuses one set of pages.
    """
    if active is None:
        active = np.ones(index.n_points, dtype=np.uint8)
    index.bound_pairs(c0, c1)  # the fits' work is the pairs: refuse an impossible block
    m = int(index.cell_start[c1] - index.cell_start[c0])
    out = _allocate(m) if buffers is None else {k: v[:m] for k, v in buffers.items()}
    has_sensor = sensor is not None
    sensor_arr = np.zeros(3) if sensor is None else np.asarray(sensor, dtype=np.float64)
    with dynamic_schedule():  # chunks of cells of unequal work
        _qc.fit_quadrics_cells(
            c0, c1, index.sorted_points, index.cell_keys, index.cell_start, index.dims,
            float(index.radius), active,
            (float(bandwidth), FRAMES[Frame(frame).value], sensor_arr, has_sensor,
             int(min_neighbors), COVARIANCES[covariance]), _outs(out),
        )
    return _mark_unfitted(out)


def _to_fit(out, bandwidth, covariance):
    return QuadricFit(
        status=out["status"], neighbors=out["npts"], beta=out["beta"], cofactor=out["cof"],
        frame=out["frames"], q=out["stats"][:, 0], sum_w=out["stats"][:, 1],
        trace_b=out["stats"][:, 2], trace_b2=out["stats"][:, 3], bandwidth=bandwidth,
        covariance=covariance,
    )


def check_neighborhoods(func, pts, neighborhoods):
    """Raise unless `neighborhoods` is a Neighborhoods over the cloud `pts`."""
    if not isinstance(neighborhoods, Neighborhoods):
        raise InvalidParameterError(f"{func}: `neighborhoods` must be a Neighborhoods instance")
    if neighborhoods.n_points != pts.shape[0]:
        raise InvalidParameterError(
            f"{func}: neighbourhoods index {neighborhoods.n_points} points but `points` has "
            f"{pts.shape[0]}"
        )


def kernel_bandwidth(func, bandwidth, neighborhoods):
    """The tricube radius of a local fit: `bandwidth` checked (> 0), or the neighbourhoods'
    radius (None for kNN: the kernel then takes each point's farthest neighbour)."""
    if bandwidth is None:
        return neighborhoods.radius
    return check_scalar(bandwidth, "bandwidth", func=func, low=0.0)


def check_fit_options(func, *, frame, covariance, min_neighbors, sensor):
    """Validate the options shared by the quadric-based functions."""
    Frame.parse(frame, "frame", func=func)
    check_option(covariance, "covariance", tuple(COVARIANCES), func=func)
    check_scalar(min_neighbors, "min_neighbors", func=func, low=7, closed="left", integer=True)
    if sensor is not None:
        s = np.asarray(sensor, dtype=np.float64)
        if s.shape != (3,) or not np.isfinite(s).all():
            raise InvalidParameterError(
                f"The 'sensor' parameter of {func} must be 3 finite coordinates. Got {sensor!r} instead."
            )


def fit_quadrics(points, neighborhoods: Neighborhoods, *, bandwidth=None, frame="z",
                 sensor=None, min_neighbors=7, covariance="sandwich") -> QuadricFit:
    """Fit the weighted second-order Taylor model (eq. 1-6) at every query point.

    Parameters
    ----------
    points : (N, 3) array_like
        The cloud the neighbourhoods index into.
    neighborhoods : Neighborhoods
        CSR neighbourhoods (rows = query points), e.g. from
        :func:`lidarstat.neighbors.radius_neighbors`.
    bandwidth : float, optional
        Tricube kernel radius b. Default: the neighbourhoods' radius; for kNN the
        distance of each point's farthest neighbour (which then gets weight 0, as in LOESS).
    frame : {'z', 'auto', 'pca'}
        ``'z'``: height is z (the paper); ``'auto'``: per point, the coordinate axis closest
        to the local PCA normal is the height (the paper's axis permutation); ``'pca'``:
        the local principal axes, height along the smallest one.
    sensor : (3,) array_like, optional
        Scanner position: normals (and so the sign of H) point toward it. Default: up.
    min_neighbors : int
        Fewer neighbours with positive weight give status TOO_FEW_NEIGHBORS (>= 7).
    covariance : {'sandwich', 'paper'}
        Cofactor to return (see :class:`QuadricFit`).

    Returns
    -------
    QuadricFit

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.neighbors import radius_neighbors
    >>> from lidarstat.features import fit_quadrics
    >>> g = np.linspace(-1, 1, 21)
    >>> x, y = [a.ravel() for a in np.meshgrid(g, g)]
    >>> pts = np.c_[x, y, 0.5 * (0.3 * x**2 + 0.1 * y**2)]
    >>> fit = fit_quadrics(pts, radius_neighbors(pts, 0.5))
    >>> np.round(fit.beta[220, 3:], 6) + 0.0   # a3, a4, a5 at the centre
    array([0.3, 0. , 0.1])
    """
    func = "fit_quadrics"
    pts = check_points(points)
    check_neighborhoods(func, pts, neighborhoods)
    check_fit_options(func, frame=frame, covariance=covariance, min_neighbors=min_neighbors,
                      sensor=sensor)
    bandwidth = kernel_bandwidth(func, bandwidth, neighborhoods)
    origin = pts.mean(axis=0)
    local = pts - origin
    sensor_local = None if sensor is None else np.asarray(sensor, float) - origin
    out = _run_kernel(local, neighborhoods.query_indices(), neighborhoods.indptr,
                      neighborhoods.indices, neighborhoods.distances, bandwidth=bandwidth,
                      frame=frame, sensor=sensor_local, min_neighbors=min_neighbors,
                      covariance=covariance)
    return _to_fit(out, bandwidth, covariance)


def unfitted_reason(status, neighbors, min_neighbors) -> str:
    """Why no point has a local model, in user terms, from the per-point statuses.

    Parameters
    ----------
    status : (N,) ndarray of uint8
        :class:`FitStatus` codes (none OK).
    neighbors : (N,) ndarray of int
        Neighbours found per point.
    min_neighbors : int
        Neighbours the model needs.

    Examples
    --------
    >>> unfitted_reason(np.array([2, 2, 1]), np.array([40, 40, 3]), 16)
    '2 of 3 points have degenerate neighbourhoods (on one line or at one location) and 1 has fewer than 16 neighbours (most: 40)'
    """
    status = np.asarray(status)
    n = status.size
    few = int((status == FitStatus.TOO_FEW_NEIGHBORS).sum())
    degenerate = int((status == FitStatus.DEGENERATE).sum())
    most = int(np.max(neighbors)) if np.size(neighbors) else 0
    parts = []
    if degenerate:
        parts.append(f"{degenerate:,} of {n:,} points have degenerate neighbourhoods "
                     "(on one line or at one location)")
    if few:
        lead = f"{few:,}" if degenerate else f"{few:,} of {n:,} points"
        verb = "has" if few == 1 and degenerate else "have"
        parts.append(f"{lead} {verb} fewer than {min_neighbors} neighbours (most: {most:,})")
    return " and ".join(parts) or f"none of {n:,} points was fitted"
