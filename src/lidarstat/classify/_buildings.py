"""Buildings among the above-ground points: tested local planes, roof patches, roof cells.

A building point of an airborne scan lies on a roof plane (or on a wall or roof edge
next to one); a tree point does not, and its pulse often gives several echoes. The test
runs on the *candidates* (points that are neither ground nor closer than
``min_object_height`` to the ground surface), with every length in metres:

1. **Noise.** ``sigma`` is the noise std along the surface normal. Unless given, it is
   estimated from the ground: the orthogonal plane of each ground point's ``k`` nearest
   ground points has a residual sum of squares ``RSS ~ sigma^2 chi2(k - 3)`` where the
   ground is locally planar, so ``sigma^2 = median(RSS) / chi2_{0.5}(k - 3)`` (the median
   is robust to the rough half of the ground: kerbs, grass, low objects).
2. **Local plane test.** Each candidate's ``k`` nearest candidates (3-D) get an
   orthogonal plane; ``T = RSS / sigma^2`` against ``chi2(k - 3)`` (upper tail, level
   ``alpha``) accepts or rejects the plane (field ``building_plane_p``).
3. **On a plane.** A candidate is on a plane when its distance to the plane of one of
   its neighbours whose own plane was accepted is within the normal test's limit:
   ``z = d / (sigma sqrt(1 + 1/k)) <= z_{1 - alpha/2}`` (``building_residual`` is the
   smallest ``z``). Roof edges, ridges and the first echoes of pulses split at an eave
   pass through the plane of the roof beside them; crowns pass through none.
4. **Roof patches.** The candidates on a plane are joined along the neighbourhood graph
   into connected patches (``building_patch``). A patch is a roof when it has at least
   ``min_points`` points and its share of non-last returns is not significantly above
   ``return_share`` (exact binomial test, level ``alpha``, ``building_patch_p``): a
   roof gives one echo per pulse except at its edges, foliage splits pulses.
5. **Roof cells.** The candidates of a roof patch at least ``min_height`` above the
   ground are building; so is every candidate at least ``min_height`` high in a
   ``cell``-metre grid cell holding such a roof point or next to one (walls, chimneys,
   dormer cheeks and roof edges that no plane test can accept on their own), unless it
   is foliage: more than 1 m above the highest roof point of those cells (0.2 m for a
   non-last return), or its ``k`` neighbours hold a share of non-last returns
   significantly above ``return_share`` (the binomial test at level ``alpha``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._shared._columns import column_min
from .._shared._memory import release_freed
from ..neighbors import knn_indices, knn_neighbors
from ..stats import binomial_test, chi2_quantile, chi2_test, z_critical
from . import _buildings_kernels as _k

__all__ = ["BUILDING_FIELDS", "BuildingTests", "building_tests", "input_order"]

#: Per-point fields of the building test: name -> (dtype, meaning).
BUILDING_FIELDS = {
    "building_plane_p": ("float64", "p-value of the chi-square test of the candidate's "
                                    "local plane (NaN: not a candidate)"),
    "building_residual": ("float64", "standardised distance to the nearest accepted "
                                     "neighbour plane (inf: none; NaN: not a candidate)"),
    "building_patch": ("int32", "connected patch of points on tested planes (0 none)"),
    "building_patch_p": ("float64", "p-value of the binomial test of the patch's share of "
                                    "non-last returns (NaN: no patch)"),
    "building_evidence": ("uint8", "0 not a candidate, 1 on a roof patch, 2 in a roof "
                                   "cell, 3 candidate that is not building"),
}

_EVIDENCE = {"none": 0, "roof": 1, "cell": 2, "other": 3}
_GROUND_QUERIES = 20_000  # ground points whose planes estimate sigma
_TOL_SINGLE = 1.0  # m: chimneys and roof edges above the highest roof point near
_TOL_MULTI = 0.2  # m: a non-last return above the roof is foliage over it


@dataclass(frozen=True)
class BuildingTests:
    """Result of :func:`building_tests` over the points it was given.

    Attributes
    ----------
    building : (N,) ndarray of bool
        Building points.
    fields : dict
        Per-point arrays named by :data:`BUILDING_FIELDS`.
    params : dict
        ``sigma`` (used), ``sigma_estimated``, ``building_alpha``, ``k``,
        ``return_share``, ``n_patches``, ``n_roof_patches``.
    """

    building: np.ndarray
    fields: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)


def ground_sigma(xy, z, ground, k, units=(1.0, 1.0)):
    """Noise std from the orthogonal planes of the ground's ``k``-neighbourhoods (None
    with fewer than ``k + 1`` ground points); on a large ground, of the points in an even
    spread of 8 m blocks. The ground is the rows `ground` of `xy` (N, 2) and `z` (N,), in
    (horizontal, vertical) `units` of metres, read in place: only the sample is copied."""
    if np.count_nonzero(ground) <= k:
        return None
    ux, uz = units
    pts = _k.ground_sample(xy, z, ground, float(ux), float(uz), 2 * _GROUND_QUERIES, 8.0)
    m = len(pts)
    query = np.arange(0, m, max(1, m // _GROUND_QUERIES))
    nb = knn_neighbors(pts, k, query=query)
    _, _, rss = _planes(pts, nb, query.size)
    return float(np.sqrt(np.median(rss) / chi2_quantile(0.5, k - 3)))


def _array_sigma(g, k):
    """:func:`ground_sigma` of the ground coordinates `g` (M, 3) in metres."""
    g = np.asarray(g, dtype=np.float64)
    return ground_sigma(np.ascontiguousarray(g[:, :2]), np.ascontiguousarray(g[:, 2]),
                        np.ones(len(g), bool), k)


def _planes(pts, nb, rows):
    centroid = np.empty((rows, 3))
    normal = np.empty((rows, 3))
    rss = np.empty(rows)
    _k.local_planes(pts, nb.indptr, nb.indices, np.arange(rows), centroid, normal, rss)
    return centroid, normal, rss


def building_tests(xyz, candidate, ground, multi, height, *, alpha=0.01, sigma=None,
                   min_points=10, min_height=2.0, return_share=0.3, cell=1.0,
                   k=12, ground_xyz=None, ground_columns=None) -> BuildingTests:
    """Building points among the candidates (module docstring; lengths in metres).

    Parameters
    ----------
    xyz : (N, 3) ndarray
        Coordinates in metres (any origin).
    candidate, ground, multi : (N,) ndarray of bool
        Points tested; ground points (for the noise estimate); non-last returns.
    height : (N,) ndarray
        Height above the ground surface (metres).
    alpha : float
        Level of the plane, residual and share tests.
    sigma : float, optional
        Noise std (metres); estimated from the ground when None.
    min_points : int
        Smallest roof patch.
    min_height : float
        Lowest building point above the ground.
    return_share : float
        Largest share of non-last returns of a roof patch under the null hypothesis.
    cell : float
        Side of the roof cells.
    k : int
        Neighbours of each local plane.
    ground_xyz : callable, optional
        ``ground_xyz() -> (M, 3) ndarray``: the coordinates (metres) of the ground points
        when they are not rows of `xyz` (then `ground` is not used). A caller that passes
        only the candidates saves the fields and copies of every other point; the array
        is made and released inside the noise estimate.
    ground_columns : tuple, optional
        ``(xy, z, mask, units)``: the ground as the rows `mask` of the planimetric
        coordinates `xy` (M, 2) and heights `z` (M,), C-contiguous float64, in
        ``units = (horizontal, vertical)`` metres, when they are not rows of `xyz` (then
        `ground` and `ground_xyz` are not used). The noise estimate reads them in place
        and copies only its sample of the ground.
    """
    n = len(xyz)
    fields = {"building_plane_p": np.full(n, np.nan), "building_residual": np.full(n, np.nan),
              "building_patch": np.zeros(n, np.int32),
              "building_patch_p": np.full(n, np.nan),
              "building_evidence": np.where(candidate, _EVIDENCE["other"],
                                            _EVIDENCE["none"]).astype(np.uint8)}
    estimated = sigma is None
    idx = np.flatnonzero(candidate)
    if estimated and ground_columns is not None:
        gxy, gz, gmask, units = ground_columns
        sigma = ground_sigma(gxy, gz, gmask, k, units=units)
    elif estimated:
        sigma = _array_sigma(xyz[ground] if ground_xyz is None else ground_xyz(), k)
    params = {"building_alpha": alpha, "k": k, "return_share": return_share,
              "sigma_estimated": estimated, "n_patches": 0, "n_roof_patches": 0}
    building = np.zeros(n, bool)
    if idx.size <= k:
        params["sigma"] = sigma
        return BuildingTests(building, fields, params)
    pts = np.ascontiguousarray(xyz[idx] - xyz[idx].mean(axis=0))
    nb = knn_indices(pts, k, func="building_tests")  # distances: not used
    release_freed()  # the search's work arrays, before the tests allocate theirs
    centroid, normal, rss = _planes(pts, nb, idx.size)
    if sigma is None:  # no ground: the candidates' own planes, the same median rule
        sigma = float(np.sqrt(np.median(rss) / chi2_quantile(0.5, k - 3)))
    sigma = max(float(sigma), 1e-4)
    params["sigma"] = sigma
    plane = chi2_test(rss / sigma**2, k - 3, alpha=alpha)
    mi = multi[idx]
    dist = np.empty(idx.size)
    owner = np.empty(idx.size, np.int64)
    n_nb_multi = np.empty(idx.size, np.int64)  # non-last returns among the k neighbours
    _k.nearest_plane_residual(pts, nb.indptr, nb.indices, centroid, normal, ~plane.reject,
                              mi, dist, owner, n_nb_multi)
    del owner, centroid, normal
    z = dist / (sigma * np.sqrt(1.0 + 1.0 / k))
    on_plane = z <= z_critical(alpha)
    patch = _k.planar_patches(nb.indptr, nb.indices, on_plane)
    del nb
    m = int(patch.max())
    size = np.bincount(patch, minlength=m + 1)[1:]
    n_multi = np.bincount(patch, weights=mi.astype(float), minlength=m + 1)[1:]
    share = binomial_test(n_multi, size, return_share, alpha=alpha)
    roof_patch = np.r_[False, (size >= min_points) & ~share.reject]
    high = height[idx] >= min_height
    roof = roof_patch[patch] & high
    top = _roof_top(pts, roof, cell)
    # foliage: a neighbourhood whose share of non-last returns is significantly above
    # `return_share` never joins a roof (every row holds k neighbours: the test of each
    # count 0..k once)
    foliage = binomial_test(np.arange(k + 1), k, return_share, alpha=alpha).reject[n_nb_multi]
    in_cell = (high & ~foliage & ~roof
               & (pts[:, 2] <= top + np.where(mi, _TOL_MULTI, _TOL_SINGLE)))
    building[idx] = roof | in_cell
    fields["building_plane_p"][idx] = plane.pvalue
    fields["building_residual"][idx] = z
    fields["building_patch"][idx] = patch.astype(np.int32)
    fields["building_patch_p"][idx] = np.r_[np.nan, share.pvalue][patch]
    ev = fields["building_evidence"]
    ev[idx[in_cell]] = _EVIDENCE["cell"]
    ev[idx[roof]] = _EVIDENCE["roof"]
    params.update(n_patches=m, n_roof_patches=int(roof_patch.sum()))
    return BuildingTests(building, fields, params)


def _roof_top(pts, roof, cell):
    """Highest roof point of the grid cell of each point and of its eight neighbours
    (-inf where none of the nine cells holds a roof point)."""
    ij = np.floor((pts[:, :2] - column_min(pts[:, :2])) / cell).astype(np.int64) + 1
    width = int(ij[:, 1].max()) + 2
    key = ij[:, 0] * width + ij[:, 1]
    top = np.full(len(pts), -np.inf)
    if not roof.any():
        return top
    ncells = (int(ij[:, 0].max()) + 2) * width
    if ncells <= 4 * len(pts):  # a table of every cell: one pass, no sort
        _k.roof_top_dense(key, roof, np.ascontiguousarray(pts[:, 2]), ncells, width, top)
        return top
    rk = key[roof]
    order = np.argsort(rk, kind="stable")
    seeds, start = np.unique(rk[order], return_index=True)
    zmax = np.maximum.reduceat(pts[roof, 2][order], start)
    _k.roof_top(key, seeds, zmax, width, top)
    return top


def input_order(fields, steps):
    """Scatter per-point `fields` through ``steps`` of ``(where, n)`` (a mask or indices
    into ``n`` points, as the classification's own arrays go back to the input order);
    the other points get NaN, or 0 for integer fields."""
    for where, n in steps:
        out = {}
        for name, a in fields.items():
            b = np.full(n, np.nan if a.dtype.kind == "f" else 0, dtype=a.dtype)
            b[where] = a
            out[name] = b
        fields = out
    return fields
