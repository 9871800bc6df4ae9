"""Final outlier test of the points the search added to a SAR-FS segment (seed 002).

Iterated data snooping with deletion residuals and a robust segment scale fixed before
the iterations (:func:`outlier_test`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..stats import t_critical


#: Most points the final outlier test removes from one segment (one per iteration).
OUTLIER_MAX = 200


#: Asymptotic efficiency of the MAD scale at the normal: ``1.4826 MAD`` of n residuals
#: has the variance of a standard deviation with ``MAD_EFFICIENCY * n`` degrees of
#: freedom (the degrees of freedom of the outlier test's t reference).
MAD_EFFICIENCY = 0.3675


def outlier_test(points, labels, units, alpha):
    """Final outlier test of the points the search added to every segment (iterated
    data snooping with a fixed robust scale).

    The points of a segment that are not in its raw cluster (the Forward Search or the
    best-fit assignment added them) are tested one at a time with their deletion
    residual from the least-squares surface of the segment's other points,
    ``w_i = e_i / (s sqrt(1 - h_ii))`` (Baarda's w-test; the point does not pull the
    surface it is tested against). The scale s is fixed before the iterations: the
    robust ``1.4826 MAD`` of all the segment's residuals about its surface, referred to
    t with ``MAD_EFFICIENCY * n`` degrees of freedom. The most significant point beyond
    the ``1 - alpha/2`` quantile leaves the segment (label 0), the surface is refitted and
    the search repeats (at most :data:`OUTLIER_MAX` points per segment), so a gross
    outlier does not mask the others. The raw clusters' points are not tested: the local
    tests accepted them. The segment's reported surface stays the raw cluster's.

    *Why a fixed scale*: with the leave-one-out scale ``s_(i)`` of the points
    still kept (Pope's tau test), every removal truncates the
    sample and shrinks the scale, so the next points cross the critical value and the
    rate on true surface points exceeds alpha. The MAD is neither inflated by gross
    outliers (no masking) nor shrunk by the removals.

    Returns the new labels, the units (accepted points and residuals updated) and per
    point the segment it was removed from (0: none).
    """
    labels = labels.copy()
    removed = np.zeros(labels.size, dtype=np.uint32)
    out = []
    for s, unit in enumerate(units, start=1):
        k = unit.raw.size
        acc, res = unit.accepted, unit.residuals
        r = unit.basis.n_terms
        mine = labels[acc] == s
        tested = (np.arange(acc.size) >= k) & mine
        if not tested.any() or mine.sum() <= r + 2:
            out.append(unit)
            continue
        A = unit.basis(unit._local_xy(points[acc]))
        rm = res[mine]
        scale = 1.4826 * float(np.median(np.abs(rm - np.median(rm))))
        if not scale > 0:
            out.append(unit)
            continue
        crit = t_critical(alpha, max(MAD_EFFICIENCY * (rm.size - r), 1.0))
        keep = np.ones(acc.size, dtype=bool)
        for _ in range(OUTLIER_MAX):
            idx = np.flatnonzero(keep & mine)
            if idx.size <= r + 1:
                break
            q, _ = np.linalg.qr(A[idx])
            e = res[idx] - q @ (q.T @ res[idx])
            h = np.minimum(np.einsum("ij,ij->i", q, q), 1.0 - 1e-12)
            t = np.where(tested[idx], np.abs(e) / (scale * np.sqrt(1.0 - h)), 0.0)
            j = int(np.argmax(t))
            if t[j] <= crit:
                break
            keep[idx[j]] = False
        if keep.all():
            out.append(unit)
            continue
        gone = acc[~keep]
        labels[gone] = 0
        removed[gone] = s
        out.append(dataclasses.replace(unit, accepted=acc[keep], residuals=res[keep]))
    return labels, out, removed
