"""The second stage of the SAR segmentation: planes the SAR units leave out.

:func:`add_planes` runs :func:`grow_planes` on the points no SAR unit took, then joins
the free points next to any plane (SAR unit of order 1 or kept grown plane, small ones
included) by the membership test (:func:`attach_points`), and returns one :class:`Segmentation` whose table has a row per
plane of either stage (column ``stage``).
"""

from __future__ import annotations

import numpy as np

from ._result import Segmentation, segment_table
from ._sar_plane_merge import MERGE_ALPHA
from ._sar_planes import PLANE_COLUMNS, attach_points, grow_planes, segment_planes

#: Neighbours of the local planes and of the membership test of the second stage.
PLANES_K = 12
#: Smallest share of a free point's `PLANES_K` neighbours in a plane for the point to be
#: on its rim (two of twelve): a point that touches a plane by one neighbour (a crown
#: over an eave) is not tested against it.
ATTACH_SHARE = 2.0 / PLANES_K


def add_planes(points, seg, *, sigma, alpha=0.05, edge_alpha=0.05, min_points=30,
               gof_alpha=0.001, k=PLANES_K, merge_alpha=MERGE_ALPHA):
    """SAR segmentation `seg` with the grown planes of the free points added.

    `sigma` is the height noise of roof planes (the SAR units' residual scale); the
    planimetric noise is estimated from the steep local planes
    (:func:`lidarstat.segment._sar_planes.planimetric_noise`). Planes of `k` to
    `min_points` - 1 points are kept when their own test accepts them; adjacent grown
    regions that are one plane are merged first at `merge_alpha` (None: no merge;
    ``params["planes_merged"]``). Segments 1..S keep their SAR rows; grown planes follow as S+1.. with ``stage`` 2, their ``normal_*``,
    ``slope_deg``, ``normal_se_deg``, ``sigma`` (residual scale), ``sigma_noise`` (the
    height noise its tests used) and the plane test ``gof_stat``, ``gof_df``, ``gof_p``
    (other SAR columns NaN, integer ones -1).
    """
    labels = np.asarray(seg.labels, dtype=np.int64)
    s1 = int(labels.max()) if labels.size else 0
    lab2, res2, tab2, sigma_h, merged = grow_planes(points, labels == 0, sigma=sigma, k=k,
                                            alpha=alpha, edge_alpha=edge_alpha,
                                            min_points=min_points, gof_alpha=gof_alpha,
                                            min_size=min(k, min_points),
                                            merge_alpha=merge_alpha)
    s2 = int(lab2.max()) if lab2.size else 0
    both = np.where(lab2 > 0, lab2 + s1, labels)
    sigma_z = np.r_[np.full(s1, float(sigma)), tab2["sigma_noise"] if s2 else np.empty(0)]
    table = seg.table
    # SAR units of order 1 and every kept plane admit points: a small plane passed its own
    # test, and the prediction band of the membership test widens with its leverage
    eligible = np.bincount(both, minlength=s1 + s2 + 1)[1:] >= min(k, min_points)
    if s1 and "degree" in table:
        eligible[:s1] &= np.asarray(table["degree"]) == 1
    final, res_att = attach_points(points, both, sigma_z, sigma_h, k=k, edge_alpha=edge_alpha,
                                   eligible=eligible, min_share=ATTACH_SHARE)
    fields = dict(seg.fields)
    residual = np.array(fields.get("surface_residual", np.full(len(points), np.nan)),
                        dtype=np.float64)
    residual[lab2 > 0] = res2[lab2 > 0]
    new = (final > 0) & (both == 0)
    cen, lam, vec = segment_planes(points, final)
    nz = np.abs(vec[:, 2, 0])
    sar_new = new & (final <= s1)
    # SAR residuals are heights: the orthogonal residual over |n_z|
    residual[sar_new] = res_att[sar_new] / np.maximum(nz[final[sar_new] - 1], 1e-9)
    residual[new & (final > s1)] = res_att[new & (final > s1)]
    fields["surface_residual"] = residual
    base = segment_table(final, points)
    out = dict(base)
    for key, col in table.items():
        if key in base:
            continue
        col = np.asarray(col)
        fill = -1 if col.dtype.kind in "iu" else np.nan
        out[key] = np.concatenate([col, np.full(s2, fill, dtype=col.dtype)])
    for key in PLANE_COLUMNS:
        vals = tab2[key] if s2 else np.empty(0)
        if key in out:
            out[key][s1:] = vals
        else:
            out[key] = np.concatenate([np.full(s1, np.nan), vals])
    out["stage"] = np.r_[np.ones(s1, np.int64), np.full(s2, 2, np.int64)]
    params = dict(seg.params)
    params.update({"planes_sigma": float(sigma), "planes_sigma_h": float(sigma_h),
                   "planes_k": k, "planes_found": s2, "planes_merged": merged,
                   "attached": int(np.count_nonzero(new))})
    result = Segmentation(final, out, seg.lines, fields, seg.method, params)
    result.units = getattr(seg, "units", [])
    result.presplit_sigma = getattr(seg, "presplit_sigma", None)
    return result
