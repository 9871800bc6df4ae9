"""Jet fitting and Monge forms (Cazals and Pouget 2005): the least-squares fit per point."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._shared._choices import Weight
from .._shared.validation import check_points, check_scalar
from ..errors import InvalidParameterError
from ..neighbors import CellIndex, Neighborhoods, knn_neighbors
from . import _jet_kernels as _jk
from ._quadric import check_fit_options, check_neighborhoods, kernel_bandwidth

MONGE_NAMES = ("k1", "k2", "b0", "b1", "b2", "b3", "c0", "c1", "c2", "c3", "c4")
_N_MONGE_OF = {1: 0, 2: 2, 3: 6, 4: 11}

@dataclass(frozen=True)
class JetFit:
    """Per-point jets and Monge forms (raw kernel outputs).

    Attributes
    ----------
    status : (N,) ndarray of uint8
        :class:`FitStatus` code (OK, TOO_FEW_NEIGHBORS or DEGENERATE).
    neighbors : (N,) ndarray of int32
        Neighbours with positive weight.
    jet : (N, 15) ndarray
        Jet coefficients in the PCA fitting frame, CGAL's order and Taylor scaling:
        ``J(u, v) = sum_k sum_i jet[k(k+1)/2 + i] u^(k-i) v^i / ((k-i)! i!)``; zero above
        the degree.
    monge : (N, 11) ndarray
        ``k1, k2, b0, b1, b2, b3, c0, c1, c2, c3, c4`` (NaN above the Monge degree).
    frame : (N, 3, 3) ndarray
        Rows d1, d2, n of the Monge basis in file coordinates, (d1, d2, n) direct, n
        toward the sensor (or up); d1 is the direction of k1 >= k2.
    monge_cofactor : (N, 11) ndarray
        Diagonal of the cofactor of `monge` (times the height variance: variances),
        first-order propagation of the jet's cofactor with the fitting frame held fixed.
    q, sum_w, trace_b, trace_b2 : (N,) ndarray
        Weighted residual sum of squares, sum of weights, tr(B), tr(B^2).
    cond : (N,) ndarray
        ``sqrt(cond_1(N))`` of the diagonally equilibrated normal matrix (about the
        condition number of the weighted design matrix).
    bandwidth : (N,) ndarray
        Kernel radius used per point.
    offset : (N,) ndarray
        Jet constant A0: height of the fitted surface above the point along the PCA normal.
    centroid : (N,) ndarray
        Distance from the point to the centroid of its neighbours (unweighted) over the
        bandwidth: about 0 inside a surface, 0.42 on a straight border (a half disc).
    degree, monge_degree : int
    weight : str
    """

    status: np.ndarray
    neighbors: np.ndarray
    jet: np.ndarray
    monge: np.ndarray
    frame: np.ndarray
    monge_cofactor: np.ndarray
    q: np.ndarray
    sum_w: np.ndarray
    trace_b: np.ndarray
    trace_b2: np.ndarray
    cond: np.ndarray
    bandwidth: np.ndarray
    offset: np.ndarray
    centroid: np.ndarray
    degree: int
    monge_degree: int
    weight: str

    def __len__(self) -> int:
        return self.status.size

    @property
    def k1(self):
        """Larger principal curvature."""
        return self.monge[:, 0]

    @property
    def k2(self):
        """Smaller principal curvature."""
        return self.monge[:, 1]

    @property
    def d1(self):
        """Unit principal direction of k1 (file coordinates)."""
        return self.frame[:, 0]

    @property
    def d2(self):
        """Unit principal direction of k2."""
        return self.frame[:, 1]

    @property
    def normal(self):
        """Unit Monge normal (toward the sensor, or up)."""
        return self.frame[:, 2]


def _allocate(m):
    return dict(status=np.zeros(m, np.uint8), npts=np.zeros(m, np.int32),
                jet=np.empty((m, 15)), monge=np.empty((m, _jk.NMONGE)),
                frames=np.empty((m, 3, 3)), stats=np.empty((m, _jk.NSTAT)),
                mcof=np.empty((m, _jk.NMONGE)))


def _to_fit(out, degree, monge_degree, weight):
    st = out["stats"]
    return JetFit(status=out["status"], neighbors=out["npts"], jet=out["jet"],
                  monge=out["monge"], frame=out["frames"], monge_cofactor=out["mcof"],
                  q=st[:, 0], sum_w=st[:, 1], trace_b=st[:, 2], trace_b2=st[:, 3],
                  cond=st[:, 4], bandwidth=st[:, 5], offset=st[:, 6], centroid=st[:, 7],
                  degree=degree,
                  monge_degree=monge_degree, weight=weight)


def _sensor(sensor, origin):
    if sensor is None:
        return np.zeros(3), False
    return np.asarray(sensor, dtype=np.float64) - origin, True


def _check_options(func, degree, monge_degree, weight, min_neighbors, sensor):
    degree = check_scalar(degree, "degree", func=func, low=1, high=4, closed="both", integer=True)
    if monge_degree is None:
        monge_degree = degree
    monge_degree = check_scalar(monge_degree, "monge_degree", func=func, low=1, high=degree,
                                closed="both", integer=True)
    weight = Weight.parse(weight, "weight", func=func)
    m = (degree + 1) * (degree + 2) // 2
    if min_neighbors is None:
        min_neighbors = m + 1
    min_neighbors = check_scalar(min_neighbors, "min_neighbors", func=func, low=m + 1,
                                 closed="left", integer=True)
    check_fit_options(func, frame="pca", covariance="sandwich", min_neighbors=max(min_neighbors, 7),
                      sensor=sensor)
    return degree, monge_degree, min_neighbors, weight


def fit_jets(points, neighborhoods: Neighborhoods | None = None, *, radius=None, query=None,
             degree=4, monge_degree=None, weight="tricube", bandwidth=None, sensor=None,
             min_neighbors=None, standard_errors=True) -> JetFit:
    """Fit a degree-`degree` jet and its Monge form at every query point.

    The four steps of Cazals and Pouget (2005): PCA frame of the neighbourhood, polynomial
    least squares in it (origin at the point), Monge basis from the Weingarten map, Monge
    coefficients (see docs/methods/jets.md).

    Parameters
    ----------
    points : (N, 3) array_like
        The cloud the neighbourhoods index into.
    neighborhoods : Neighborhoods, optional
        CSR neighbourhoods, e.g. from :func:`lidarstat.neighbors.radius_neighbors` or
        :func:`~lidarstat.neighbors.knn_neighbors`. Give these or `radius`.
    radius : float, optional
        Fit the points within `radius` of each query point, searching and fitting a block
        of grid cells at a time: no neighbour table is built, so the memory is that of
        the result whatever the number of neighbours (the fits equal those over
        ``radius_neighbors(points, radius, query=query)`` up to the order of the sums).
    query : (M,) array_like of int, optional
        With `radius`: the points to fit (default all), in this order.
    degree : int
        Jet degree d, 1 to 4 (15 coefficients at 4).
    monge_degree : int, optional
        Monge degree d' <= d (default d): 2 gives k1, k2 and directions, 3 adds b0..b3,
        4 adds c0..c4.
    weight : {'tricube', 'none'}
        Tricube kernel weights of the distance (as the quadric), or CGAL's unweighted fit.
    bandwidth : float, optional
        Kernel radius. Default: the neighbourhoods' radius, or for kNN each point's
        farthest neighbour distance (which then has weight 0 with tricube).
    sensor : (3,) array_like, optional
        Normals are oriented toward it (default: up).
    min_neighbors : int, optional
        Fewer neighbours (positive weight) give TOO_FEW_NEIGHBORS; default and minimum is
        the number of coefficients plus one.
    standard_errors : bool
        Propagate the jet's cofactor to the Monge coefficients (``monge_cofactor``);
        about 20 % of the time at degree 4.

    Returns
    -------
    JetFit

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.neighbors import radius_neighbors
    >>> from lidarstat.features import fit_jets
    >>> g = np.linspace(-1, 1, 41)
    >>> x, y = [a.ravel() for a in np.meshgrid(g, g)]
    >>> pts = np.c_[x, y, 0.5 * (0.3 * x**2 - 0.1 * y**2) + x**4 / 24]
    >>> fit = fit_jets(pts, radius_neighbors(pts, 0.4), degree=4)
    >>> np.round(fit.monge[840], 6) + 0.0   # k1, k2, b0..b3, c0..c4 at the centre
    array([ 0.3, -0.1,  0. ,  0. ,  0. ,  0. ,  1. ,  0. ,  0. ,  0. ,  0. ])
    >>> np.round(fit_jets(pts, radius=0.4, query=[840]).monge[0, :2], 6) + 0.0
    array([ 0.3, -0.1])
    """
    func = "fit_jets"
    pts = check_points(points)
    degree, monge_degree, min_neighbors, weight = _check_options(
        func, degree, monge_degree, weight, min_neighbors, sensor)
    if neighborhoods is None:
        return _fit_radius(pts, radius, query, bandwidth, func,
                           dict(degree=degree, monge_degree=monge_degree, weight=weight,
                                sensor=sensor, min_neighbors=min_neighbors,
                                standard_errors=standard_errors))
    for name, value in (("radius", radius), ("query", query)):
        if value is not None:
            raise InvalidParameterError(f"{func}: `{name}` is for a search by radius; the "
                                        "given `neighborhoods` already hold theirs")
    check_neighborhoods(func, pts, neighborhoods)
    bandwidth = kernel_bandwidth(func, bandwidth, neighborhoods)
    origin = pts.mean(axis=0)
    local = pts - origin
    sensor_arr, has_sensor = _sensor(sensor, origin)
    query = neighborhoods.query_indices()
    out = _allocate(query.size)
    params = (-1.0 if bandwidth is None else float(bandwidth), degree, monge_degree,
              weight == "tricube", sensor_arr, has_sensor, int(min_neighbors),
              bool(standard_errors))
    _jk.fit_jets_block(local, query, neighborhoods.indptr, neighborhoods.indices,
                       neighborhoods.distances, params, _outs(out))
    return _to_fit(out, degree, monge_degree, weight)


def _fit_radius(pts, radius, query, bandwidth, func, kw, block_size=131072):
    """:func:`fit_jets` by `radius` with the fused search, rows in `query` order."""
    if radius is None:
        raise InvalidParameterError(f"{func}: give `neighborhoods` or `radius`")
    if bandwidth is not None:
        raise InvalidParameterError(f"{func}: `bandwidth` is the `radius` of a search by "
                                    "radius; give one of them")
    radius = check_scalar(radius, "radius", func=func, low=0.0)
    n = pts.shape[0]
    if query is None:
        rows = np.arange(n, dtype=np.int64)
    else:
        rows = np.asarray(query)
        if rows.ndim != 1 or (rows.size and (not np.issubdtype(rows.dtype, np.integer)
                                             or rows.min() < 0 or rows.max() >= n)):
            raise InvalidParameterError(f"{func}: `query` must be a 1-d array of point "
                                        f"indices in [0, {n})")
    unique, inverse = np.unique(rows, return_inverse=True)
    active = np.zeros(n, bool)
    active[unique] = True
    slot = np.zeros(n, np.int64)
    slot[unique] = np.arange(unique.size)
    out = _allocate(unique.size)
    _fit_into(pts, radius, active, kw, block_size, out, slot)
    if unique.size != rows.size or not np.array_equal(unique, rows):
        out = {k: v[inverse] for k, v in out.items()}
    return _to_fit(out, kw["degree"], kw["monge_degree"], kw["weight"])


def _outs(out):
    """The output tuple of the jet kernels (``_jet_kernels._jet_point``)."""
    return (out["status"], out["npts"], out["jet"], out["monge"], out["frames"], out["stats"],
            out["mcof"])


def _fit_cells(index, *, degree, monge_degree, weight, sensor, min_neighbors, standard_errors,
               block_size, progress, active=None):
    """Fused search + fit over a CellIndex, block by block; outputs in input order.

    `active` (bool, input order) restricts the fits to those points; the other rows are
    marked SKIPPED."""
    n = index.n_points
    out = _allocate(n)
    sensor_arr, has_sensor = _sensor(sensor, index.origin)
    params = (float(index.radius), degree, monge_degree, weight == "tricube", sensor_arr,
              has_sensor, int(min_neighbors), bool(standard_errors))
    active = (np.ones(n, np.uint8) if active is None
              else np.ascontiguousarray(active[index.order], dtype=np.uint8))
    done = 0
    for c0, c1 in index.cell_blocks(block_size):
        s0, s1 = index.cell_start[c0], index.cell_start[c1]
        index.bound_pairs(c0, c1)  # the fits' work is the pairs: refuse an impossible block
        part = {k: v[s0:s1] for k, v in out.items()}
        _jk.fit_jets_cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start,
                           index.dims, float(index.radius), active, params, _outs(part))
        done += s1 - s0
        if progress is not None:
            progress(done, n)
    inverse = np.empty_like(index.order)
    inverse[index.order] = np.arange(n)
    return {k: np.take(v, inverse, axis=0) for k, v in out.items()}


def _fit_into(points, radius, active, kw, block_size, dest, slot):
    """The jets at `radius` of the points where `active` (bool, input order), written to
    row ``slot[i]`` of every array of `dest` (:func:`._jet_fit._allocate`) for input
    index i, a block of cells at a time: the fits of :func:`_fit_cells` without its
    whole-cloud output arrays."""
    index = CellIndex(points, radius)
    sensor_arr, has_sensor = _sensor(kw["sensor"], index.origin)
    params = (float(index.radius), kw["degree"], kw["monge_degree"],
              kw["weight"] == "tricube", sensor_arr, has_sensor, int(kw["min_neighbors"]),
              bool(kw["standard_errors"]))
    act = np.ascontiguousarray(active[index.order], dtype=np.uint8)
    for c0, c1 in index.cell_blocks(block_size):
        s0, s1 = int(index.cell_start[c0]), int(index.cell_start[c1])
        index.bound_pairs(c0, c1)  # the fits' work is the pairs: refuse an impossible block
        sel = act[s0:s1] != 0
        if not sel.any():
            continue
        part = _allocate(s1 - s0)
        _jk.fit_jets_cells(c0, c1, index.sorted_points, index.cell_keys, index.cell_start,
                           index.dims, float(index.radius), act, params, _outs(part))
        rows = slot[index.order[s0:s1][sel]]
        for key, val in part.items():
            dest[key][rows] = val[sel]


@dataclass(frozen=True)
class PrincipalDirections:
    """Principal curvatures and directions per point (see :func:`principal_directions`)."""

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normal: np.ndarray
    status: np.ndarray


def principal_directions(points, neighborhoods=None, *, radius=None, k=None, degree=2,
                         weight="tricube", sensor=None) -> PrincipalDirections:
    """Principal curvatures k1 >= k2 and their unit directions d1, d2 at every point.

    A jet of degree `degree` (2: the osculating quadric in the PCA frame; 3 or 4 reduce
    the bias of strongly curved or noisy surfaces) and its Monge basis. Give CSR
    `neighborhoods` or one of `radius` / `k`.

    Returns
    -------
    PrincipalDirections
        ``k1``, ``k2`` (N,), ``d1``, ``d2``, ``normal`` (N, 3) unit vectors with
        (d1, d2, normal) direct and the normal toward `sensor` (or up); NaN where the fit
        failed (``status`` != 0).

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.synth import make_surface
    >>> from lidarstat.features import principal_directions
    >>> cloud = make_surface("cylinder", sigma=0.0, rng=0)
    >>> pd = principal_directions(cloud.xyz, radius=0.25, degree=4)
    >>> i = int(np.argmax(cloud.edge_distance))
    >>> bool(abs(pd.k2[i] - cloud.kmin[i]) < 1e-3 and abs(pd.k1[i]) < 1e-3)
    True
    """
    func = "principal_directions"
    pts = check_points(points)
    given = sum(x is not None for x in (neighborhoods, radius, k))
    if given != 1:
        raise InvalidParameterError(f"{func}: give exactly one of `neighborhoods`, `radius`, `k`")
    if neighborhoods is None:
        if radius is not None:
            from ..neighbors import radius_neighbors
            neighborhoods = radius_neighbors(pts, radius)
        else:
            neighborhoods = knn_neighbors(pts, k)
    fit = fit_jets(pts, neighborhoods, degree=degree, monge_degree=2, weight=weight,
                   sensor=sensor, standard_errors=False)
    return PrincipalDirections(k1=fit.k1, k2=fit.k2, d1=fit.d1, d2=fit.d2, normal=fit.normal,
                               status=fit.status)
