"""The tile functions of ``covariance``, ``ridges`` and ``segment`` on a catalogue
(``segment``'s in ``_catalogue_segment``) and the area-wide helpers they share.

Each command has three parts, as in :data:`lidarstat.cli._catalogue.TILE_METHODS`:

* ``buffer(args, catalogue)``: the default ``--buffer``, the method's reach;
* ``prepare(args, catalogue)``: what must be decided once for the whole area before the
  tiles run (the noise sigma, which each tile would otherwise estimate on its own
  points; the k-nearest-neighbour reach);
* ``fields(args, extra)``: the function computing a tile's fields on a
  :class:`lidarstat.pipeline.BufferedTile` (core points first, then the buffer), calling
  the public library functions the single-file command calls.

Reaches (the buffer that makes the result independent of the tiling):

* ``covariance``: two neighbourhoods. A point's features use its neighbours' points;
  ``CurvatureVariance`` and ``NormalVariation`` use its neighbours' features. With
  ``--radius`` the buffer is ``2 x radius``; with ``--k`` twice the k-th-neighbour
  reach (:func:`knn_reach`: the largest distance to the k-th neighbour on the largest
  tile, times 1.5 for tiles sparser than that one); at the automatic scale (neither)
  twice the reach of its largest neighbourhood, ``OPTIMAL_K_MAX`` neighbours.
* ``ridges``: the jets reach one radius; a ridge point compares its neighbours' jets,
  and the ridge lines are traced through them and kept when at least ``--min-length``
  (two radii by default) long: ``3 x radius`` (with ``--k``, the k-th-neighbour reach;
  at the automatic scale, the largest radius of the area's ladder, :func:`area_ladder`).
  The per-point jets are then independent of the tiling; the ridge lines are not quite:
  a line longer than the buffer is traced in pieces, and the line test's Bonferroni
  count (the cloud's independent neighbourhoods) is the tile's with its buffer.
* ``segment``: segmentations couple points further than any buffer. A scale the method
  chooses from the data is chosen once for the area (:func:`segment_scale`): the SAR
  bandwidth, the curvature ladder (and noise), the ridges' radius. Each tile is
  segmented with a buffer (default: the method's neighbourhood reach times 4, so that
  the segments near a tile's border grow over the neighbours' points as on the whole
  area), and the segments of neighbouring tiles are joined where they hold the same
  points of the tiles' overlap (``_catalogue_segment``): a surface crossing tile
  borders keeps one id over the area.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["AREA_SAMPLE_TILES", "COVARIANCE", "RIDGES", "TILE_OPTIONS", "area_ladder",
           "covariance_decide", "curvature_ladder", "jet_ladder", "knn_reach",
           "ridges_decide", "sample_tiles"]

#: The options each command's tile function passes on (destinations). Any other option
#: given with a catalogue is refused rather than ignored, so an option added to a command
#: later is refused on catalogues until its tile function passes it on.
TILE_OPTIONS = {
    "curvature": frozenset({"radius", "sigma", "noise", "sensor", "alpha", "test", "frame",
                            "min_neighbors", "minimal_detectable"}),
    "covariance": frozenset({"k", "radius", "sensor", "sigma", "noise", "alpha", "eigen_mode",
                             "boundary", "boundary_alpha", "curvature_threshold",
                             "variance_threshold", "curved", "curved_alpha", "border_band",
                             "jump_alpha"}),
    "ridges": frozenset({"radius", "k", "sigma", "alpha", "weight", "sensor", "noise",
                         "ratio", "min_length"}),
}

#: Margin on the k-th-neighbour reach measured on one tile, for tiles sparser than it.
KNN_MARGIN = 1.5


def _largest(cat) -> int:
    return max(range(len(cat)), key=lambda i: cat.files[i].n_points)


#: Tiles (spread evenly over the catalogue's order) on which an automatic scale is
#: decided for the area.
AREA_SAMPLE_TILES = 9


def sample_tiles(cat) -> list[int]:
    """The tiles an area's scale is decided on: up to :data:`AREA_SAMPLE_TILES`, spread
    evenly over the catalogue."""
    import numpy as np

    n = len(cat)
    return sorted({int(i) for i in np.linspace(0, n - 1, min(n, AREA_SAMPLE_TILES)).round()})


def area_ladder(cat, ladder_of) -> tuple[float, ...]:
    """One ladder of radii for the whole area: per rung, the median over a sample of
    tiles (:data:`AREA_SAMPLE_TILES`, one read at a time) of ``ladder_of(xyz)``, each
    tile's ladder from its own density.

    An automatic scale reads its ladder from the cloud's density; a tile would read its
    own, and a point's result would depend on the tile it lies in. Given this ladder,
    every tile runs the whole area's automatic scale.
    """
    import numpy as np

    ladders = [np.asarray(ladder_of(cat.tile_xyz(i)), dtype=np.float64)
               for i in sample_tiles(cat)]
    return tuple(float(r) for r in np.median(np.vstack(ladders), axis=0))


def jet_ladder(xyz):
    """The jets' automatic ladder of a tile (its density measured on 20,000 points)."""
    from ..features import radius_ladder

    return radius_ladder(xyz, sample=20000)


def curvature_ladder(xyz):
    """The tested curvature's automatic ladder of a tile."""
    from ..features import scale_ladder

    return scale_ladder(xyz)


def _cached(args, name, compute):
    """A decision for the area, made once per run (buffer and tiles share it)."""
    key = f"_area_{name}"
    if getattr(args, key, None) is None:
        setattr(args, key, compute())
    return getattr(args, key)


def _ladder_text(ladder):
    return ", ".join(f"{r:.4g}" for r in ladder)


def knn_reach(cat, k: int) -> float:
    """The largest 3-D distance to the `k`-th neighbour on the catalogue's largest tile,
    times :data:`KNN_MARGIN`: a conservative reach of k-nearest-neighbour methods."""
    import numpy as np
    from scipy.spatial import cKDTree

    xyz = cat.tile_xyz(_largest(cat))
    k = min(int(k), len(xyz))
    d = cKDTree(xyz).query(xyz, k=k, workers=-1)[0]
    return KNN_MARGIN * float(np.max(d[:, -1] if d.ndim > 1 else d))


def _outputs(args, cat) -> dict:
    return {f.path: p for f, p in zip(cat.files, cat.outputs(args.output, args.template))}


def _offsets(cat) -> dict:
    """Tile path -> points in the tiles before it: per-tile ids made unique."""
    return dict(zip((f.path for f in cat.files), cat.point_offsets()))


def _say(args, text):
    if not args.quiet:
        print(f"  {text}")


def _scalar_sigma(sigma, what):
    import numpy as np

    from ..errors import InvalidParameterError

    if np.ndim(sigma) != 0:
        raise InvalidParameterError(f"{what}: the noise estimated on one tile is a model of "
                                    "the range, not one value for the area; give --sigma "
                                    "with a catalogue of tiles")
    return float(sigma)


def _neighbourhood_reach(args, cat, command):
    """The reach of ``--radius`` (the largest of several scales) or ``--k``; a scale
    chosen during the run is not known before it, so a buffer must then be given."""
    from ..errors import InvalidParameterError

    radius = getattr(args, "radius", None)
    if isinstance(radius, (list, tuple)):
        radius = max(radius) if radius else None
    if isinstance(radius, (int, float)):
        return float(radius)
    k = getattr(args, "k", None)
    if isinstance(k, int):
        return knn_reach(cat, k)
    raise InvalidParameterError(f"--buffer: {command} on a catalogue of tiles needs "
                                "--buffer, --radius or --k (a neighbourhood chosen during "
                                "the run is not known before the tiles are read)")


# -------------------------------------------------------------------------- covariance
def _covariance_reach(args, cat):
    if args.k is None and args.radius is None:  # the automatic scale: at most OPTIMAL_K_MAX
        from ..features import OPTIMAL_K_MAX

        return knn_reach(cat, OPTIMAL_K_MAX)
    return _neighbourhood_reach(args, cat, "covariance")


def _covariance_buffer(args, cat):
    return 2.0 * _covariance_reach(args, cat)


def _covariance_prepare(args, cat):
    return {"outputs": _outputs(args, cat), **covariance_decide(args, cat)}


def covariance_decide(args, cat):
    """One noise sigma for the area (estimated on the largest tile when not given)."""
    extra = {}
    if args.sigma is not None:
        return extra
    from ..classify import covariance
    from .covariance import classification_options

    i = _largest(cat)
    res = covariance(cat.tile_xyz(i), k=args.k, radius=args.radius,
                     sensor=args.sensor, noise=args.noise, alpha=args.alpha,
                     eigen_mode=args.eigen_mode,
                     **classification_options(args, args.sensor))
    extra["sigma"] = _scalar_sigma(res.classes.sigma, "covariance")
    _say(args, f"sigma {extra['sigma']:.4g} estimated on {cat.files[i].path.name}, used for "
         "every tile")
    return extra


def _covariance_fields(args, extra):
    from ..classify import covariance
    from .covariance import classification_options

    sigma = extra.get("sigma", args.sigma)
    opts = classification_options(args, args.sensor)

    def fields(tile):
        res = covariance(tile.xyz, k=args.k, radius=args.radius, sensor=args.sensor,
                         sigma=sigma, noise=args.noise, alpha=args.alpha,
                         eigen_mode=args.eigen_mode, **opts)
        return res.to_fields(), {}

    return fields


COVARIANCE = (_covariance_buffer, _covariance_fields, _covariance_prepare)


# ------------------------------------------------------------------------------ ridges
def _ridges_ladder(args, cat):
    """The area's ladder of the jets' automatic scale (neither --radius nor --k)."""
    if args.radius is not None or args.k is not None:
        return None
    return _cached(args, "jet_ladder", lambda: area_ladder(cat, jet_ladder))


def _jet_reach(args, cat):
    ladder = _ridges_ladder(args, cat)
    if ladder is not None:
        return max(ladder)
    return _neighbourhood_reach(args, cat, "ridges")


def _ridges_buffer(args, cat):
    return 3.0 * _jet_reach(args, cat)


def _ridges_prepare(args, cat):
    return {"outputs": _outputs(args, cat), "offsets": _offsets(cat),
            "extents": [f.bounds2d for f in cat.files], **ridges_decide(args, cat)}


def ridges_decide(args, cat):
    """One noise sigma for the area (the jets' estimate on the largest tile) and, at the
    automatic scale, one ladder of radii."""
    extra = {"scales": _ridges_ladder(args, cat)}
    if extra["scales"] is not None:
        _say(args, f"automatic scale: radii {_ladder_text(extra['scales'])} decided on "
             f"{len(sample_tiles(cat))} tiles, used for every tile")
    if args.sigma is not None:
        return extra
    from ..features import jets

    i = _largest(cat)
    res = jets(cat.tile_xyz(i), radius=args.radius, k=args.k, alpha=args.alpha,
               degree=4, weight=args.weight, sensor=args.sensor, noise=args.noise,
               standard_errors=False, scales=extra["scales"])
    extra["sigma"] = _scalar_sigma(res.sigma, "ridges")
    _say(args, f"sigma {extra['sigma']:.4g} estimated on {cat.files[i].path.name}, used for "
         "every tile")
    return extra


def _lines_in_tile(lines, extent, extents=None, index=None):
    """The lines whose middle vertex lies in the tile (each line written by one tile).

    With `extents` (every tile's ``(xmin, ymin, xmax, ymax)``) and the tile's `index`:
    the lines whose middle vertex is nearest to this tile's extent (ties to the first
    tile), so that a line in the gap between two tiles' point bounds is kept once too.
    """
    import numpy as np

    if lines is None or not len(lines):
        return lines
    mid = np.array([v[len(v) // 2, :2] for v in lines.vertices]).reshape(-1, 2)
    if extents is None:
        keep = ((mid[:, 0] >= extent.xmin) & (mid[:, 0] <= extent.xmax)
                & (mid[:, 1] >= extent.ymin) & (mid[:, 1] <= extent.ymax))
    else:
        box = np.asarray(extents, float).reshape(-1, 1, 4)
        dx = np.maximum(np.maximum(box[..., 0] - mid[:, 0], mid[:, 0] - box[..., 2]), 0)
        dy = np.maximum(np.maximum(box[..., 1] - mid[:, 1], mid[:, 1] - box[..., 3]), 0)
        keep = np.argmin(np.hypot(dx, dy), axis=0) == index
    return type(lines)([v for v, k in zip(lines.vertices, keep) if k],
                       {n: np.asarray(a)[keep] for n, a in lines.attributes.items()})


def _ridges_fields(args, extra):
    import numpy as np

    from ..segment import ridges

    sigma = extra.get("sigma", args.sigma)

    def fields(tile):
        res = ridges(tile.xyz, radius=args.radius, k=args.k, sigma=sigma, alpha=args.alpha,
                     weight=args.weight, sensor=args.sensor, noise=args.noise,
                     ratio=args.ratio, min_length=args.min_length,
                     scales=extra.get("scales"))
        out = Path(extra["outputs"][tile.extent.path])
        index = list(extra["outputs"]).index(tile.extent.path)
        lines = _lines_in_tile(res.lines, tile.extent, extra["extents"], index)
        # line ids unique over the area, in the points' field and the lines alike
        offset = extra["offsets"][tile.extent.path]
        if "line_id" in lines.attributes:
            lines.attributes["line_id"] = lines.attributes["line_id"] + offset
        lines.write(out.with_name(out.name.split(".")[0] + ".ridges.geojson"),
                    crs=tile.core.crs)
        f = res.to_fields()
        f["ridge_line"] = np.where(f["ridge_line"] > 0, f["ridge_line"] + offset,
                                   0).astype(f["ridge_line"].dtype)
        return f, {"lines": len(lines)}

    return fields


RIDGES = (_ridges_buffer, _ridges_fields, _ridges_prepare)
