"""The automatic scale of the tested curvature: a ladder of radii and, per point, the
smallest radius whose tests detect the curvature seen (seed 000, eq. 19-21, per point).

Design (see docs/methods/curvature.md, "Automatic scale"): radii ``r_1 < ... < r_L`` in
point spacings. Walking up, a point stops at the first rung ``r_k`` whose model test
accepts the quadric and where its curvature is detected with the required power (both
principal curvatures and H at least ``z_{1-alpha/4} + z_power`` standard deviations from
0: eq. 19 with the estimates as K0, H0). A point that never stops (planes, cylinders: one
principal curvature is 0) keeps the largest rung whose model test accepts the quadric,
where the tests have the most power; one rejected at every rung is MODEL_REJECTED.
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidParameterError
from ..neighbors import knn_neighbors
from ..stats import normal_pvalue, normal_quantile, z_critical

#: The ladder, in point spacings: 3 spacings hold about 28 points (the smallest
#: neighbourhood with a usable chi-square test), each rung doubles the area.
LADDER_SPACINGS = (3.0, 3.0 * 2 ** 0.5, 6.0, 6.0 * 2 ** 0.5, 12.0)

#: Neighbours used to measure the spacing (the point itself included).
SPACING_K = 13


def point_spacing(points, *, sample=20000, rng=0):
    """Typical point spacing of a surface sample: ``r_12 sqrt(pi / 12)``, median over up
    to `sample` points, where ``r_12`` is the distance to the 12th neighbour (the spacing
    of a square grid of the same areal density).
    """
    pts = np.asarray(points, dtype=np.float64)
    n = pts.shape[0]
    if n < SPACING_K:
        raise InvalidParameterError(
            f"the automatic scale needs at least {SPACING_K} distinct points (got {n}); "
            "give a radius")
    gen = np.random.default_rng(rng)
    q = np.sort(gen.choice(n, size=min(int(sample), n), replace=False))
    nb = knn_neighbors(pts, SPACING_K, query=q)
    r = nb.distances.reshape(q.size, SPACING_K)[:, -1]
    r = r[r > 0]
    if r.size == 0:
        raise InvalidParameterError("the automatic scale cannot measure the point spacing: "
                                    "the points share their locations; give a radius")
    return float(np.median(r) * np.sqrt(np.pi / (SPACING_K - 1)))


def scale_ladder(points, *, sample=20000, rng=0):
    """The automatic ladder of radii for `points`: :data:`LADDER_SPACINGS` times
    :func:`point_spacing`."""
    s = point_spacing(points, sample=sample, rng=rng)
    return tuple(float(m * s) for m in LADDER_SPACINGS)


def stop_pvalue(alpha, power):
    """Two-sided p-value below which a curvature is detected with `power` (eq. 19):
    ``|est| / sd >= z_{1-alpha/4} + z_power``."""
    return normal_pvalue(z_critical(alpha / 2) + normal_quantile(power))


def walk_ladder(run, radii, *, n, alpha, power):
    """Per point, the radius of the design above.

    `run(radius, active, into)` computes the fields of :func:`curvature` at one radius for
    the `active` points (None: all): with `into` None it returns them for every point,
    otherwise it hands each block to `into(rows, block_fields)` (`rows`: the block's input
    positions) and keeps nothing, so that a rung writes straight into the chosen fields.

    A point is fitted at every rung until its curvature is detected with `power`; it keeps
    the fields of the smallest rung where that happens, else of the largest rung whose
    model test accepts the quadric, else (rejected at every rung) of the first rung.

    Returns the fields at the chosen radii and the chosen radius per point.
    """
    p_stop = stop_pvalue(alpha, power)
    fields = run(radii[0], None, None)
    chosen = np.full(n, radii[0])
    pending = ~((fields["chi2_pass"] == 1) & _detected(fields, p_stop))
    for r in radii[1:]:
        if not pending.any():
            break
        run(r, pending, climb_into(fields, chosen, pending, r,
                                   stop=lambda res, take: take & _detected(res, p_stop)))
    return fields, chosen


def climb_into(fields, chosen, pending, radius, *, stop):
    """The block writer of one rung: a pending point whose model test accepts the quadric
    at `radius` takes that rung's fields and radius; it leaves the climb where
    `stop(block_fields, taken)` is true.

    `fields`, `chosen` and `pending` (per input point) are updated in place. A rung reads
    `pending` once, before its first block (the points it fits), and every point lies in
    exactly one block, so clearing a block's rows does not change the rung's work.
    """
    def into(rows, res):
        take = pending[rows] & (res["chi2_pass"] == 1)
        dest = rows[take]
        for k, v in fields.items():
            v[dest] = res[k][take]
        chosen[dest] = radius
        pending[rows[stop(res, take)]] = False
    return into


def _detected(fields, p_stop):
    """Curvature detected with the required power: H and both principal curvatures."""
    return (fields["H_p"] <= p_stop) & (fields["K_p"] <= p_stop)
