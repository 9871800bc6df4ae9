"""SAR-FS refinement of given raw clusters into the final segments (seed 002, section 5.4).

:func:`refine_raw_clusters` refines every raw cluster within its search area
(:func:`refine_cluster`), gives every point to the unit it fits best, merges units on one
surface, refits the final segments, applies the final outlier test and the per-segment
goodness-of-fit test (with the split of the segments it rejects), intersects adjacent
surfaces into break lines and assembles the table of :class:`Segmentation`.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared._threads import single_blas_thread
from .._shared.validation import check_option, check_scalar
from ..errors import InvalidParameterError, LidarstatWarning
from ._forward_search import STOP_RULES, StopRule
from ._grow import relabel
from ._intersect import intersection_lines
from ._result import Polylines, Segmentation, segment_table
from ._sar_gof import split_misfits
from ._sar_merge import assign, final_units, merge_groups, refit_group, two_hop_contacts
from ._sar_outliers import outlier_test
from ._sar_refine import refine_cluster
from ._search_area import delaunay_graph, search_areas

#: Forward Search stop reasons written to the table (``fs_stop``).
STOP_CODES = {"exhausted": 0, "f": 1, "residual": 2, "not searched": 3}


def _table(points, labels, units, keep_units):
    table = segment_table(labels, points)
    s = len(keep_units)
    max_deg = max((units[u].degree for u in keep_units), default=1)
    powers = [(i - j, j) for i in range(max_deg + 1) for j in range(i + 1)]
    cols = {k: np.full(s, np.nan) for k in
            ["degree", "n_s", "n_sa", "m", "rho", "se_rho", "sigma_sar", "sigma", "E0", "N0",
             "normal_x", "normal_y", "normal_z", "slope_deg", "normal_se_deg", "fs_stop",
             "rho_points", "frame"]}
    for pe, pn in powers:
        cols[f"c_{pe}{pn}"] = np.full(s, np.nan)
        cols[f"se_c_{pe}{pn}"] = np.full(s, np.nan)
    for k, u in enumerate(keep_units):
        unit = units[u]
        cols["degree"][k] = unit.degree
        cols["n_s"][k], cols["n_sa"][k], cols["m"][k] = unit.n_s, unit.n_sa, unit.m
        cols["rho"][k] = unit.fit.rho
        cols["se_rho"][k] = unit.fit.se_rho
        cols["sigma_sar"][k] = np.sqrt(unit.fit.sigma2)
        cols["sigma"][k] = unit.sigma
        cols["E0"][k], cols["N0"][k] = unit.basis.center
        cols["frame"][k] = 0 if unit.frame is None else 1
        if unit.frame is None:  # coefficients of z(E, N); a wall's are in its own frame
            pw, coef, se = unit.monomials()
            for (pe, pn), c, e in zip(pw, coef, se):
                cols[f"c_{pe}{pn}"][k] = c
                cols[f"se_c_{pe}{pn}"][k] = e
        else:
            cols["E0"][k] = cols["N0"][k] = np.nan
        cen = np.array([[table["centroid_x"][k], table["centroid_y"][k],
                         table["centroid_z"][k]]])
        nrm = unit.normal(cen)[0]
        cols["normal_x"][k], cols["normal_y"][k], cols["normal_z"][k] = nrm
        cols["slope_deg"][k] = np.degrees(np.arccos(nrm[2]))
        if np.all(np.isfinite(unit.surface_cov)):
            cols["normal_se_deg"][k] = unit.normal_error(cen)[0]
        cols["fs_stop"][k] = STOP_CODES[unit.fs.stop_reason]
        cols["rho_points"][k] = unit.rho_points
    for k in ("degree", "n_s", "n_sa", "m", "fs_stop", "rho_points", "frame"):
        cols[k] = cols[k].astype(np.int64)
    table.update(cols)
    return table


@renamed_parameters(threshold="search", alpha="fs_alpha", alpha_residual="envelope_alpha",
                    stop="fs_stop", block="fs_block", min_size="min_points")
@single_blas_thread
def refine_raw_clusters(points, raw_labels, *, search, w_radius, degrees=1, max_degree=3,
                        fs_alpha=0.001, envelope_alpha=0.001, fs_stop="both", fs_block=1,
                        max_steps=500, min_points=10, merge_alpha=0.01, outlier_alpha=0.01,
                        sigma=None, gof_alpha=0.001, graph=None, progress=None):
    """SAR-FS refinement of given raw clusters; returns a :class:`Segmentation`.

    Parameters
    ----------
    points : (N, 3) ndarray
        Coordinates.
    raw_labels : (N,) ndarray of int
        Raw clusters 1..C (0: none).
    search : float
        Search-area path length (section 5.3).
    w_radius : float
        Radius of the SAR adjacency.
    degrees : int, None or (C,) array
        Polynomial order per cluster (None: t tests up to `max_degree`).
    fs_alpha, envelope_alpha, fs_stop, fs_block, max_steps
        Forward Search settings (`alpha`, `envelope_alpha`, `stop`, `block`, `max_steps`
        of :func:`forward_search`); `fs_alpha` is also the level of the t tests of the
        order when `degrees` is None.
    min_points : int
        Smallest raw cluster refined and smallest final segment.
    merge_alpha : float or None
        Adjacent units of the same order are merged when the Chow F test does not reject
        one common surface at this level (a plane split into two raw clusters by a dormer
        or a chimney becomes one unit again; their Table 6 sizes are summed), unless the
        union fails the test against the noise `sigma` (level `gof_alpha`) that each part
        passes (a crease, :func:`crease_refuses`). None: no merging.
    outlier_alpha : float or None
        Level of the final outlier test, per point (iterated data snooping with deletion
        residuals, :func:`outlier_test`; default 0.01; Baarda's usual 0.001 lets wall
        and leaf points 3-3.5 sigma off the plane stay, docs/methods/sar.md): points
        added to a segment by the search (not in its raw cluster) whose residual is
        significant leave the segment (field ``surface_outlier``: the segment they left;
        table ``n_outliers``). None: no test.
    sigma : float, optional
        A priori height noise (marginal standard deviation) of the per-segment
        goodness-of-fit test; None: no test.
    gof_alpha : float or None
        Level of the per-segment goodness-of-fit test (:func:`split_misfits`): the
        residual scale of a segment's points about their own least-squares surface
        against `sigma`, chi-square with Satterthwaite's degrees of freedom under the SAR
        correlation of the residuals (:func:`lidarstat.stats.sar_variance_test`). A
        segment it rejects is split in two surfaces (normals 2-means, then k-surfaces)
        when that removes at least half of its residual sum of squares, and the parts are
        refitted, given the outlier test and tested again (table ``gof_stat``, ``gof_df``,
        ``gof_p``, ``scale_ratio``, ``split``). None: no test.
    graph : tuple, optional
        Precomputed :func:`delaunay_graph`.
    progress : callable, optional
        ``progress(done, total)`` after each cluster.
    """
    func = "refine_raw_clusters"
    # Checked here once: refine_cluster would refuse them cluster by cluster.
    fs_stop = StopRule(check_option(fs_stop, "fs_stop", STOP_RULES, func=func)).value
    fs_block = check_scalar(fs_block, "fs_block", func=func, low=1, closed="left",
                            integer=True)
    max_steps = check_scalar(max_steps, "max_steps", func=func, low=1, closed="left",
                             integer=True)
    min_points = check_scalar(min_points, "min_points", func=func, low=1, closed="left",
                              integer=True)
    fs_alpha = check_scalar(fs_alpha, "fs_alpha", func=func, low=0.0, high=1.0)
    envelope_alpha = check_scalar(envelope_alpha, "envelope_alpha", func=func, low=0.0,
                                  high=1.0)
    search = check_scalar(search, "search", func=func, low=0.0)
    w_radius = check_scalar(w_radius, "w_radius", func=func, low=0.0)
    for name, level in (("outlier_alpha", outlier_alpha), ("gof_alpha", gof_alpha),
                        ("merge_alpha", merge_alpha)):
        if level is not None:
            check_scalar(level, name, func=func, low=0.0, high=1.0)
    n = points.shape[0]
    raw_labels = relabel(raw_labels, min_points)
    graph = graph if graph is not None else delaunay_graph(points)
    areas = search_areas(points, raw_labels, search, graph=graph)
    c_max = int(raw_labels.max()) if n else 0
    order = np.argsort(raw_labels, kind="stable")
    starts = np.searchsorted(raw_labels[order], np.arange(1, c_max + 2))
    units, skipped = [], []
    for c in range(1, c_max + 1):
        raw = order[starts[c - 1]:starts[c]]
        extra = areas.indices[areas.indptr[c - 1]:areas.indptr[c]]
        deg = degrees if degrees is None or np.isscalar(degrees) else int(degrees[c - 1])
        try:
            unit = refine_cluster(points, raw, extra, w_radius=w_radius,
                                  degree=deg, max_degree=max_degree, alpha=fs_alpha,
                                  envelope_alpha=envelope_alpha, stop=fs_stop, block=fs_block,
                                  max_steps=max_steps, covariance=False)
            units.append(unit)
        except (np.linalg.LinAlgError, InvalidParameterError, ValueError) as exc:
            skipped.append((c, int(raw.size), str(exc)))
        if progress is not None:
            progress(c, c_max)
    if skipped:
        warnings.warn(f"{len(skipped)} raw clusters could not be modelled (first: cluster "
                      f"{skipped[0][0]}, {skipped[0][1]} points: {skipped[0][2]})",
                      LidarstatWarning, stacklevel=3)
    unit_labels = assign(units, n)
    if merge_alpha is not None and len(units) > 1:
        root = merge_groups(points, unit_labels, units, graph, merge_alpha, search,
                            sigma2=None if sigma is None else float(sigma) ** 2,
                            crease_alpha=gof_alpha)
        groups = {}
        for u in range(1, len(units) + 1):
            groups.setdefault(int(root[u]), []).append(u)
        new_units, new_of = [], np.zeros(len(units) + 1, dtype=np.int64)
        for _, members in sorted(groups.items()):
            merged = None
            if len(members) > 1:
                idx = np.flatnonzero(np.isin(unit_labels, members))
                try:
                    merged = refit_group(points, idx, [units[u - 1] for u in members],
                                         w_radius)
                except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                    merged = None  # keep the members apart
            if merged is not None:
                new_units.append(merged)
                new_of[members] = len(new_units)
            else:
                for u in members:
                    new_units.append(units[u - 1])
                    new_of[u] = len(new_units)
        unit_labels = new_of[unit_labels]
        units = new_units
    labels = relabel(unit_labels, max(int(min_points), 1))
    # segment s (1..S) -> unit index
    keep_units = []
    for s in range(1, int(labels.max()) + 1 if n else 1):
        u = np.bincount(unit_labels[labels == s]).argmax() - 1
        keep_units.append(int(u))
    kept = final_units(points, labels, [units[u] for u in keep_units], w_radius)
    outlier = np.zeros(n, dtype=np.uint32)  # segment a point was removed from (0: none)
    if outlier_alpha is not None:
        labels, kept, outlier = outlier_test(points, labels, kept, outlier_alpha)
    presplit_sigma = np.array([u.sigma for u in kept])
    gof = np.full((len(kept), 5), np.nan)
    gof[:, 4] = 0
    t_gof = time.perf_counter()
    if sigma is not None and gof_alpha is not None and kept:
        labels, kept, outlier, gof = split_misfits(
            points, labels, kept, outlier, sigma2=float(sigma) ** 2, alpha=gof_alpha,
            w_radius=w_radius, outlier_alpha=outlier_alpha, min_points=max(int(min_points), 1))
    t_gof = time.perf_counter() - t_gof
    table = _table(points, labels, kept, list(range(len(kept))))
    table["n_outliers"] = np.bincount(outlier, minlength=len(kept) + 1)[1:].astype(np.int64)
    for k, name in enumerate(("gof_stat", "gof_df", "gof_p", "scale_ratio")):
        table[name] = gof[:, k]
    table["split"] = gof[:, 4].astype(np.int64)
    if len(kept) > 1:
        pts_c, seg_c = two_hop_contacts(graph, labels)
        lines = intersection_lines(points, labels, kept, pts_c, seg_c, max_shift=search)
    else:
        lines = Polylines([], {})
    residual = np.full(n, np.nan)
    for s, unit in enumerate(kept, start=1):
        mine = labels[unit.accepted] == s
        residual[unit.accepted[mine]] = unit.residuals[mine]
    fields = {"raw_cluster": raw_labels.astype(np.uint32), "surface_residual": residual,
              "surface_outlier": outlier}
    params = {"search": search, "w_radius": w_radius, "fs_alpha": fs_alpha,
              "envelope_alpha": envelope_alpha, "fs_stop": fs_stop, "fs_block": fs_block,
              "max_steps": max_steps, "min_points": min_points, "merge_alpha": merge_alpha,
              "outlier_alpha": outlier_alpha, "raw_clusters": c_max, "skipped": skipped,
              "gof_alpha": gof_alpha,
              "splits": int(np.count_nonzero(gof[:, 4])), "gof_seconds": round(t_gof, 3)}
    seg = Segmentation(labels, table, lines, fields, "sar", params)
    seg.units = kept
    seg.presplit_sigma = presplit_sigma  # the noise re-estimate of segment_sar uses these
    return seg
