"""Mixed nonparametric + parametric segmentation (Crosilla, Visintini and Sepic 2005).

:func:`segment_sar` chains the four steps of seed 002 and returns a
:class:`~lidarstat.segment.Segmentation`:

1. local plane regression of every point (:func:`lidarstat.features.local_planes`);
2. raw clusters by region growing on tested height and slope agreement
   (:func:`raw_clusters`);
3. a search area per raw cluster over the Delaunay triangulation (:func:`search_areas`);
4. SAR-FS refinement of every raw cluster within its search area
   (:func:`refine_raw_clusters`, :mod:`._sar_units`); points claimed by several units go
   to the one they fit best (smallest standardised residual); adjacent surfaces are
   intersected into break lines.
"""

from __future__ import annotations

import numpy as np

from .._shared._deprecate import renamed_parameters
from .._shared._geometry import mean_spacing as _mean_spacing
from .._shared._threads import single_blas_thread
from .._shared.validation import check_option, check_points, check_scalar
from ..neighbors import check_copies, radius_neighbors
from ._forward_search import STOP_RULES, StopRule
from ._raw_clusters import raw_clusters
from ._sar_stages import add_planes
from ._sar_units import refine_raw_clusters
from ._search_area import delaunay_graph

#: When the noise is estimated, a second pass uses the median residual standard deviation
#: of the first pass's units if it exceeds the local (lower-quartile) estimate by this
#: factor (see :func:`segment_sar`, `sigma`).
SIGMA_RATIO = 1.25


#: Units whose residual standard deviation exceeds this multiple of the local noise
#: estimate are not planes at that noise (terrain, trees, curved or merged faces) and do
#: not enter the units' noise estimate.
SIGMA_UNIT_MAX = 3.0


class _PlaneFields:
    """What the SAR segmentation keeps of its local planes: their noise, the adaptive
    rule used and the per-point fields it writes (``z0``, ``slope_e``, ``slope_n``,
    ``plane_pass``)."""

    def __init__(self, fit):
        f = fit.to_fields()  # the slopes are columns of the coefficients: copied
        self.fields = {name: np.array(f[name])
                       for name in ("z0", "slope_e", "slope_n", "plane_pass")}
        self.sigma = float(np.sqrt(fit.sigma2))
        self.adaptive = fit.params.get("adaptive")


def _units_noise(sd, sigma_local):
    """Median residual standard deviation `sd` of the units that can be planes at the
    noise level: those within :data:`SIGMA_UNIT_MAX` times the local estimate (NaN if
    none). The units are those before the goodness-of-fit split (a split of a rough
    plane would hide the roughness the re-estimate looks for)."""
    sd = np.asarray(sd, dtype=np.float64)
    sd = sd[np.isfinite(sd) & (sd <= SIGMA_UNIT_MAX * sigma_local)]
    return float(np.median(sd)) if sd.size else np.nan


@renamed_parameters(bandwidth="radius", alpha_residual="envelope_alpha", min_size="min_points",
                    threshold="search", stop="fs_stop", block="fs_block")
@single_blas_thread
def segment_sar(points, *, radius=None, sigma=None, alpha=0.05, edge_alpha=0.05,
                fs_alpha=0.001, envelope_alpha=0.001, fs_stop="both", degree=1, max_degree=3,
                adaptive="multiscale", criterion="rice", grow_radius=None, search=None,
                w_radius=None, min_points=30, fs_block=1, max_steps=500, outlier_alpha=0.01,
                gof_alpha=0.001, planes=True, progress=None, rng=0):
    """Segment a cloud into planar (or polynomial) surface units by SAR-FS (seed 002).

    Parameters
    ----------
    points : (N, 3) array_like
        Coordinates (E, N, height).
    radius : float, optional
        Plane-regression bandwidth b (planimetric kernel half-width of the local planes);
        default chosen by :func:`lidarstat.features.select_plane_bandwidth` with
        `criterion`.
    sigma : float, optional
        Height noise. Default: estimated in up to two passes. The first uses the lower
        quartile of the local-plane variances (the noise of the smoothest surfaces); when
        the median residual standard deviation of the resulting units about their
        fitted surfaces (units within :data:`SIGMA_UNIT_MAX` times that estimate: the
        others are not planes at this noise) exceeds it by more than
        :data:`SIGMA_RATIO` (real surveys: strip offsets, roof texture), the
        segmentation is redone with that median, the noise about actual roof planes.
        ``params`` records ``sigma_local``, ``sigma_units`` and ``sigma_passes``.
    alpha : float
        Level of the local planarity test.
    edge_alpha : float
        Level of the height and slope tests of region growing.
    fs_alpha : float
        Level of the Forward Search F test (and of the t tests of the order when
        `degree` is None).
    envelope_alpha : float
        Level of the Forward Search deletion-residual envelope.
    fs_stop : StopRule or {'both', 'f', 'residual'}
        Forward Search stopping rule (:func:`forward_search`, ``stop``).
    degree : int or None
        Polynomial order of every unit (1: planes); None chooses it by t tests.
    max_degree : int
        Largest order considered when `degree` is None.
    adaptive : bool, AdaptiveBandwidth or {'multiscale', 'geary', 'none'}
        Per-point bandwidths of the local planes. ``'multiscale'`` (default): every point
        takes the largest of b, 0.75 b, 0.5 b whose local plane passes the planarity test,
        and raw clusters grow only through points planar at b (the others are attached,
        never expand), so faces narrower than the automatic b keep their edge points
        without windows bridging hip lines. ``True``/``'geary'``: Geary's local
        indicator (section 4.1). ``False``/``'none'``: one b for the whole cloud.
    criterion : BandwidthCriterion or {'rice', 'gcv', 'press'}
        Bandwidth selector when `radius` is None.
    grow_radius : float, optional
        Radius of the region-growing graph (default ``min(b, 2 * spacing)``).
    search : float, optional
        Search-area path length (default 3 b).
    w_radius : float, optional
        Radius of the SAR adjacency W (default ``1.5 * spacing``).
    min_points : int
        Smallest raw cluster and final segment (points).
    fs_block : int
        Points added per Forward Search step (1: unitary search).
    max_steps : int
        Most Forward Search steps per raw cluster (the block grows to fit).
    outlier_alpha : float or None
        Level of the final per-point outlier test (:func:`refine_raw_clusters`).
    gof_alpha : float or None
        Level of the per-segment goodness-of-fit test against the noise `sigma` (given or
        estimated) and of the split of the segments it rejects (:func:`refine_raw_clusters`).
    planes : bool
        Second stage (:func:`add_planes`): planes in their own frame among the points no
        SAR unit took (steep faces, walls, faces narrower than b), grown by tested
        membership, then the free points next to any plane joined to it by the same
        membership test. Table column ``stage`` (1: SAR unit, 2: grown plane).
    progress : callable, optional
        ``progress(done, total)``.
    rng : int or Generator
        Seed of the bandwidth subsample.

    Returns
    -------
    Segmentation
        ``labels`` (0: no unit), the table (Table 6 sizes ``n_s``, ``n_sa``, ``m``; ``rho``,
        ``sigma``; surface coefficients ``c_pq`` of ``(E - E0)^p (N - N0)^q`` with
        standard errors; normal and slope at the centroid), the intersection lines,
        per-point ``raw_cluster``, ``z0``, ``slope_e``, ``slope_n``, ``plane_pass``,
        ``surface_residual``, ``surface_outlier``, and ``params`` (every setting used,
        under the names above, with the estimated bandwidth and noise).

    Examples
    --------
    >>> import numpy as np
    >>> from lidarstat.segment import segment_sar
    >>> rng = np.random.default_rng(0)
    >>> xy = rng.uniform(0, 20, (4000, 2))
    >>> z = np.where(xy[:, 0] < 10, 0.5 * xy[:, 0], 10 - 0.5 * xy[:, 0])   # a gable roof
    >>> seg = segment_sar(np.c_[xy, z + rng.normal(0, 0.03, 4000)], radius=1.5)
    >>> seg.n_segments, np.round(np.abs(seg.table["c_10"]), 2).tolist()
    (2, [0.5, 0.5])
    """
    from ..features import (AdaptiveBandwidth, BandwidthCriterion, local_planes,
                            select_plane_bandwidth)

    func = "segment_sar"
    points = check_points(points, min_points=10)
    fs_stop = StopRule(check_option(fs_stop, "fs_stop", STOP_RULES, func=func)).value
    criterion = BandwidthCriterion(check_option(
        criterion, "criterion", [m.value for m in BandwidthCriterion], func=func)).value
    if not isinstance(adaptive, bool):
        adaptive = AdaptiveBandwidth(check_option(
            adaptive, "adaptive", [m.value for m in AdaptiveBandwidth], func=func)).value
    min_points = check_scalar(min_points, "min_points", func=func, low=1, closed="left",
                              integer=True)
    for name, level in (("alpha", alpha), ("edge_alpha", edge_alpha), ("fs_alpha", fs_alpha),
                        ("envelope_alpha", envelope_alpha), ("outlier_alpha", outlier_alpha),
                        ("gof_alpha", gof_alpha)):
        if level is not None or name not in ("outlier_alpha", "gof_alpha"):
            check_scalar(level, name, func=func, low=0.0, high=1.0)
    fs_block = check_scalar(fs_block, "fs_block", func=func, low=1, closed="left",
                            integer=True)
    if sigma is not None:
        sigma = check_scalar(sigma, "sigma", func=func, low=0.0)
    if radius is not None:
        radius = check_scalar(radius, "radius", func=func, low=0.0)
    check_copies(points, what=func)  # neighbors/_duplicates.py
    selected = radius is None
    if selected:
        radius = select_plane_bandwidth(points, criterion=criterion, rng=rng).bandwidth
    b = check_scalar(radius, "radius", func=func, low=0.0)
    spacing = _mean_spacing(points)
    grow_radius = (min(b, 2.0 * spacing) if grow_radius is None else
                   check_scalar(grow_radius, "grow_radius", func=func, low=0.0))
    search = (3.0 * b if search is None else check_scalar(search, "search", func=func, low=0.0))
    w_radius = (1.5 * spacing if w_radius is None else
                check_scalar(w_radius, "w_radius", func=func, low=0.0))
    graph = delaunay_graph(points)
    nbh = radius_neighbors(points, grow_radius, dim=2)

    def one_pass(noise):
        fit = local_planes(points, b, sigma=noise, alpha=alpha, adaptive=adaptive)
        core = (fit.bandwidth >= b) if fit.params.get("adaptive") == "multiscale" else None
        raw = raw_clusters(points, fit, nbh, alpha=edge_alpha, min_points=min_points,
                           core=core)
        # of the local planes only their noise and four output fields are used from here
        # on: the rest (coefficients, covariances, statistics: some 200 bytes a point)
        # is released before the units' search allocates its own
        kept, labels = _PlaneFields(fit), raw.labels
        del fit, core, raw
        seg = refine_raw_clusters(points, labels, search=search, w_radius=w_radius,
                                  degrees=degree, max_degree=max_degree, fs_alpha=fs_alpha,
                                  envelope_alpha=envelope_alpha, fs_stop=fs_stop,
                                  fs_block=fs_block, max_steps=max_steps,
                                  min_points=min_points, graph=graph,
                                  outlier_alpha=outlier_alpha,
                                  sigma=kept.sigma, gof_alpha=gof_alpha,
                                  progress=progress)
        return kept, seg

    fit, seg = one_pass(sigma)
    sigma_local = fit.sigma
    sigma_units = _units_noise(seg.presplit_sigma, sigma_local)
    passes = 1
    if sigma is None and sigma_units > SIGMA_RATIO * sigma_local:
        fit, seg = one_pass(sigma_units)
        passes = 2
    graph = nbh = None  # the passes' neighbourhoods, released before the planes stage
    if planes:
        noise = sigma_units if sigma is None and np.isfinite(sigma_units) else fit.sigma
        seg = add_planes(points, seg, sigma=noise, alpha=alpha, edge_alpha=edge_alpha,
                         min_points=min_points, gof_alpha=gof_alpha)
    seg.fields.update(fit.fields)
    seg.params.update({"radius": b, "radius_selected_by": criterion if selected else None,
                       "sigma": fit.sigma, "sigma_local": sigma_local,
                       "sigma_units": sigma_units, "sigma_passes": passes, "alpha": alpha,
                       "edge_alpha": edge_alpha, "grow_radius": grow_radius,
                       "spacing": spacing, "adaptive": fit.adaptive,
                       "degree": degree, "max_degree": max_degree, "planes": planes})
    return seg
