"""Per-segment goodness-of-fit test of the SAR-FS segments and the split of those it rejects.

The residual scale of every segment about its own least-squares surface is tested
against the survey noise with the SAR correlation of the residuals
(:func:`lidarstat.stats.sar_variance_test`; the correlation is estimated only when
Moran's test of the residuals rejects, and kept when the likelihood-ratio test of rho = 0
rejects). A rejected segment is split into two surfaces (:mod:`._sar_split`) when that
removes most of its residual sum of squares.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import InvalidParameterError
from ..stats import (likelihood_ratio_test, moran_test, sar_fit, sar_variance_test,
                     z_critical)
from ._sar_outliers import outlier_test
from ._sar_refine import MAX_SEARCH, _adjacency, _standardised, refit_unit
from ._sar_split import robust_core, two_surfaces


#: A segment whose goodness-of-fit test rejects is split in two only when the two parts'
#: pooled residual sum of squares is at most this share of the segment's: the lack of
#: fit is structure (another face), not a false rejection or a slightly rough plane.
SPLIT_GAIN = 0.5
#: Most successive splits of one segment (a segment of three faces needs two).
SPLIT_DEPTH = 3
#: Largest segment that is split (larger ones are tested only): leaked raw clusters are
#: roof faces of a few hundred points, whereas terrain pieces between buildings (not
#: planes, always rejected) would be split down to SPLIT_DEPTH at the cost of many ML
#: refits of large units (doubled the run time on an AHN3 tile).
SPLIT_MAX = 5000
#: Points on which the correlation of a segment's residuals is estimated (nearest the
#: medoid); segments larger than MAX_SEARCH are neither tested nor split.
NOISE_RHO_MAX = 150
#: Level of Moran's test and of the likelihood-ratio test of rho = 0 that decide whether
#: a segment's residuals are correlated (:func:`_noise_rho`).
NOISE_RHO_ALPHA = 0.05


def _unit_heights(unit, xyz):
    """Planimetric coordinates and heights of points in a unit's frame."""
    if unit.frame is None:
        return xyz[:, :2], xyz[:, 2]
    local = (xyz - unit.frame[0]) @ unit.frame[1:].T
    return local[:, :2], local[:, 2]


def _noise_rho(xy, e, w_radius, q=None):
    """SAR interaction of a segment's residuals: 0 unless Moran's I test of the residuals
    (:func:`lidarstat.stats.moran_test`, two-sided at :data:`NOISE_RHO_ALPHA`) rejects;
    then the ML estimate on at most NOISE_RHO_MAX points near the medoid, kept when the
    likelihood-ratio test of rho = 0 (:func:`lidarstat.stats.likelihood_ratio_test`) also
    rejects. (Moran's test first: one sparse product instead of an ML fit for every
    segment.)"""
    if q is not None:
        W = _standardised(_adjacency(xy, w_radius))
        if not moran_test(e, q, W, alpha=NOISE_RHO_ALPHA).reject:
            return 0.0
    if e.size > NOISE_RHO_MAX:
        med = np.median(xy, axis=0)
        keep = np.argsort(np.sum((xy - med) ** 2, axis=1))[:NOISE_RHO_MAX]
        xy, e = xy[keep], e[keep]
    W = _standardised(_adjacency(xy, w_radius))
    n = e.size
    try:
        fit = sar_fit(e, np.ones((n, 1)), W, grid=7, xatol=1e-4, covariance=False)
    except (InvalidParameterError, ValueError, np.linalg.LinAlgError):
        return 0.0
    d = e - e.mean()
    ll0 = -0.5 * n * (np.log(max(float(d @ d), 1e-300) / n) + np.log(2 * np.pi) + 1.0)
    lr = likelihood_ratio_test(fit.loglik, ll0, 1, alpha=NOISE_RHO_ALPHA)
    return fit.rho if lr.reject else 0.0


def _scale_test(points, idx, unit, sigma2, w_radius, alpha):
    """Goodness of fit of segment `idx` (its points' residual scale about their own
    least-squares surface against the noise `sigma2`), with the SAR correlation of the
    residuals (:func:`lidarstat.stats.sar_variance_test`). Returns the test and the
    residual sum of squares."""
    xy, z = _unit_heights(unit, points[idx])
    A = unit.basis.monomials(xy)  # the same column space, no triangular solve
    q, _ = np.linalg.qr(A)
    e = z - q @ (q.T @ z)
    rho = _noise_rho(xy, e, w_radius, q)
    W = _standardised(_adjacency(xy, w_radius)) if rho else None
    return sar_variance_test(z, A, W, rho, sigma2, alpha=alpha), float(e @ e)


def split_misfits(points, labels, units, removed, *, sigma2, alpha, w_radius,
                  outlier_alpha, min_points):
    """Per-segment goodness-of-fit test and the split of the segments it rejects.

    Every segment (up to MAX_SEARCH points) is tested by :func:`_scale_test`. A rejected
    segment (up to :data:`SPLIT_MAX` points) is split in two by :func:`two_surfaces`
    when the split leaves at most :data:`SPLIT_GAIN` of its residual sum of squares; each
    part is refitted on its share of the raw cluster (:func:`refit_unit`), given the
    final outlier test again, and
    tested again (at most :data:`SPLIT_DEPTH` successive splits). Parts below `min_points`
    are not made (the split is refused). A part that is still rejected but cannot be
    split (pieces of further faces smaller than `min_points`) loses its points off its
    main surface (:func:`robust_core`, the outlier test's critical value; recorded in
    ``removed`` like the outlier test's) and is refitted and tested again; this counts
    as one more step of `SPLIT_DEPTH`.

    Returns labels, units, removed (as :func:`outlier_test`) and per segment the test
    statistic, its degrees of freedom, the p-value, the scale ratio ``s / sigma`` and the
    split depth.
    """
    n = labels.size
    out_level = outlier_alpha if outlier_alpha is not None else 0.01
    removed = removed.astype(np.int64)  # key of the work item a point was removed from
    order = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[order], np.arange(len(units) + 2))
    work = [(order[starts[s]:starts[s + 1]], u, 0, s) for s, u in enumerate(units, start=1)]
    next_key = len(units) + 1
    done = []
    nan4 = (np.nan, np.nan, np.nan, np.nan)
    while work:
        idx, unit, depth, key = work.pop(0)
        r = unit.basis.n_terms
        if idx.size > MAX_SEARCH or idx.size <= r + 1:
            done.append((idx, unit, depth, nan4, key))
            continue
        test, rss = _scale_test(points, idx, unit, sigma2, w_radius, alpha)
        stats = (float(test.statistic), float(test.df), float(test.pvalue),
                 float(np.sqrt(rss / (idx.size - r) / sigma2)))
        parts = None
        if bool(test.reject) and depth < SPLIT_DEPTH and idx.size <= SPLIT_MAX:
            xy, z = _unit_heights(unit, points[idx])
            parts = two_surfaces(xy, z, unit.basis, min_points)
            if parts is not None and parts[1] > SPLIT_GAIN * rss:
                parts = None
        if parts is None and bool(test.reject) and 0 < depth < SPLIT_DEPTH \
                and idx.size <= SPLIT_MAX:
            # a part of a split raw cluster that is still not one surface (pieces of
            # further faces too small for a part of their own): its points off the main
            # surface (robust fit, the outlier test's critical value) leave it
            xy, z = _unit_heights(unit, points[idx])
            off = robust_core(xy, z, unit.basis, z_critical(out_level))
            if 0 < off.sum() <= idx.size // 2:
                removed[idx[off]] = key
                keep = idx[~off]
                raw = unit.raw[np.isin(unit.raw, keep)]
                try:
                    sub = refit_unit(points, raw, keep[~np.isin(keep, raw)],
                                     w_radius=w_radius, degree=unit.degree,
                                     rho_hint=unit.fit.rho, fs=unit.fs)
                    work.append((keep, dataclasses.replace(sub, n_s=int(raw.size),
                                                           n_sa=unit.n_sa, m=unit.m),
                                 depth + 1, key))
                    continue
                except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                    removed[idx[off]] = 0
        if parts is None:
            done.append((idx, unit, depth, stats, key))
            continue
        g = parts[0]
        # the points the outlier test removed from the segment go to the part whose
        # surface they fit better, and are tested again there
        back = np.flatnonzero(removed == key)
        removed[back] = 0
        if back.size:
            xy, z = _unit_heights(unit, points[idx])
            xyb, zb = _unit_heights(unit, points[back])
            A, Ab = unit.basis.monomials(xy), unit.basis.monomials(xyb)
            res = [np.abs(zb - Ab @ np.linalg.lstsq(A[m], z[m], rcond=None)[0])
                   for m in (g, ~g)]
            to1 = res[0] <= res[1]
            parts_idx = (np.r_[idx[g], back[to1]], np.r_[idx[~g], back[~to1]])
        else:
            parts_idx = (idx[g], idx[~g])
        for part in parts_idx:
            raw = unit.raw[np.isin(unit.raw, part)]
            try:
                sub = refit_unit(points, raw, part[~np.isin(part, raw)], w_radius=w_radius,
                                 degree=unit.degree, rho_hint=unit.fit.rho, fs=unit.fs)
            except (np.linalg.LinAlgError, InvalidParameterError, ValueError):
                sub = None
            if sub is None:
                done.append((part, unit, depth + 1, nan4, 0))
                continue
            sub = dataclasses.replace(sub, n_s=int(raw.size), n_sa=unit.n_sa, m=unit.m)
            if outlier_alpha is not None:
                lab = np.zeros(n, dtype=np.int64)
                lab[part] = 1
                # every point of a part is tested: its raw cluster was shown not to be
                # one surface, so the local tests' acceptance no longer exempts it
                lab, (tst,), gone = outlier_test(
                    points, lab, [dataclasses.replace(sub, raw=sub.raw[:0])], outlier_alpha)
                sub = dataclasses.replace(tst, raw=sub.raw[np.isin(sub.raw, tst.accepted)])
                removed[gone > 0] = next_key
                part = np.flatnonzero(lab == 1)
            work.append((part, sub, depth + 1, next_key))
            next_key += 1
    new = np.zeros(n, dtype=np.int64)
    new_of_key = np.zeros(next_key, dtype=np.int64)
    out_units, info = [], []
    for idx, unit, depth, st, key in done:
        out_units.append(unit)
        info.append((*st, depth))
        new[idx] = len(out_units)
        new_of_key[key] = len(out_units) if key else 0
    return (new, out_units, new_of_key[removed].astype(np.uint32),
            np.array(info, dtype=float).reshape(-1, 5))
