"""The ``moments`` command on a catalogue: its tile function, the road cut decided once
for the area, the terrain model per tile and the area's report page.

Part of :mod:`lidarstat.cli._catalogue` (the :data:`TILE_METHODS` entry of ``moments``).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["MOMENTS", "ROAD_SAMPLE_POINTS", "area_report"]


def _moments_prepare(args, cat):
    """Where each tile's terrain model and report go (named after its output), and the
    road cut decided once for the area."""
    outputs = cat.outputs(args.output, args.template)
    if args.dtm:
        Path(args.dtm).mkdir(parents=True, exist_ok=True)
    report = None
    if not args.no_report:
        report = Path(args.report) if args.report else Path(args.output) / "report"
    extra = {"outputs": {f.path: p for f, p in zip(cat.files, outputs)}, "report": report}
    if not args.no_intensity:
        extra["road_threshold"] = _area_road_cut(args, cat)
    return extra


#: Points of the sample on which a catalogue's road cut is decided (every tile thinned
#: by one step; the whole area when it holds fewer points).
ROAD_SAMPLE_POINTS = 2_000_000


def _area_road_cut(args, cat):
    """The road cut of the whole area: ``moments`` on every tile thinned to at most
    :data:`ROAD_SAMPLE_POINTS` points in all (the whole area when smaller); -inf when
    the area's ground intensity has no road cluster. Each tile would otherwise cut its
    own ground's intensity, and a tile with little road finds another cut or none."""
    import numpy as np

    from ..classify import moments
    from ..io import linear_units, read

    step = max(1, -(-cat.n_points // ROAD_SAMPLE_POINTS))
    names = ("intensity", "number_of_returns", "return_number")
    xyz, attrs = [], {n: [] for n in names}
    for f in cat.files:  # copies of every step-th point: a tile is freed once sampled
        c = read(f.path, fields=names)
        xyz.append(c.xyz[::step].copy())
        for n in names:
            a = c.attributes.get(n)
            attrs[n].append(None if a is None else np.asarray(a)[::step].copy())
        del c
    attrs = {n: (None if any(a is None for a in v) else np.concatenate(v))
             for n, v in attrs.items()}
    if attrs["intensity"] is None:
        return None
    units = linear_units(cat.crs, units=args.units, scale=args.scale, source="catalogue")
    res = moments(np.concatenate(xyz), attrs["intensity"],
                  number_of_returns=attrs["number_of_returns"],
                  return_number=attrs["return_number"], method=args.method,
                  window=args.window, min_window=args.min_window, alpha=args.alpha,
                  min_points=args.min_points, cycle=args.cycle, bandwidth=args.bandwidth,
                  surface_cell=args.surface_cell, elevation_rule=args.elevation_rule,
                  workers=args.workers, scheduler="threads",
                  opening_window=args.opening_window, iterations=args.iterations,
                  units=units, low_noise=not args.no_low_noise, road_rule=args.road_rule,
                  ground_spread=args.ground_spread, continuity=not args.no_continuity,
                  terrain=not args.no_terrain, rng=args.seed, source="catalogue")
    cut = res.params["road_threshold"]
    if not args.quiet:
        where = "the whole area" if step == 1 else f"every {step}th point of the area"
        print(f"  road cut {'none (no road cluster)' if cut is None else f'{cut:.6g}'} "
              f"decided on {where}, used for every tile")
    return float("-inf") if cut is None else cut


def _moments_buffer(args, cat):
    from ..io import linear_units

    units = linear_units(cat.crs, units=args.units, scale=args.scale, source="catalogue")
    return args.window / units.horizontal


def _moments_fields(args, extra):
    from ..classify import moments
    from ..io import linear_units, write_geotiff
    from ..pipeline import terrain_model
    from ..report import write_moments_report

    def fields(tile):
        core = tile.core
        units = linear_units(core.crs, units=args.units, scale=args.scale,
                             header=core.las_header, source=str(tile.extent.path))
        res = moments(
            tile.xyz, None if args.no_intensity else tile.attribute("intensity"),
            number_of_returns=tile.attribute("number_of_returns"),
            return_number=tile.attribute("return_number"), method=args.method,
            window=args.window, min_window=args.min_window, alpha=args.alpha,
            min_points=args.min_points, cycle=args.cycle, bandwidth=args.bandwidth,
            surface_cell=args.surface_cell, elevation_rule=args.elevation_rule,
            workers=1, scheduler="sync", opening_window=args.opening_window,
            iterations=args.iterations, units=units, low_noise=not args.no_low_noise,
            road_rule=args.road_rule, ground_spread=args.ground_spread,
            continuity=not args.no_continuity, rng=args.seed, source=str(tile.extent.path),
            road_threshold=extra.get("road_threshold"), terrain=not args.no_terrain,
            building_alpha=args.building_alpha, sigma=args.sigma)
        stem = Path(extra["outputs"][tile.extent.path]).stem
        fields = res.to_fields()
        if extra.get("report") is not None:
            write_moments_report(extra["report"] / "tiles" / stem, res, max_plots=12,
                                 input_path=tile.extent.path)
        del res  # the classifier's arrays go before the terrain model is built
        if args.dtm:  # the tile's extent, from the ground of the tile and its buffer
            e = tile.extent
            dtm = terrain_model(tile.xyz, fields["classification"],
                                resolution=args.dtm_resolution / units.horizontal,
                                bounds=(e.xmin, e.ymin, e.xmax, e.ymax), crs=core.crs)
            write_geotiff(Path(args.dtm) / f"{stem}.tif", dtm)
        return fields, {}

    return fields


MOMENTS = (_moments_buffer, _moments_fields, _moments_prepare)


def area_report(folder, args, cat, runs, buffer, seconds, mosaic=None):
    """One page for the area: the classes of every tile on one map, shares per tile, the
    terrain model's hillshade, and each tile's moment analyses behind a link."""
    import numpy as np

    from ..io import read, read_geotiff
    from ..report import ASPRS_COLOURS, write_run_report

    step = max(1, -(-cat.n_points // 1_500_000))  # at most ~1.5M points on the map
    xyz, cls, rows, links = [], [], [], {}
    for r in runs:
        c = read(r.output, fields=["classification"])
        k = np.asarray(c.attributes["classification"])
        xyz.append(c.xyz[::step])
        cls.append(k[::step])
        codes, n = np.unique(k, return_counts=True)
        row = {"tile": r.input.name, "points": len(k)}
        page = folder / "tiles" / r.output.stem / "index.html"
        if page.exists():
            links[f"{r.input.name}: moment analyses"] = f"tiles/{r.output.stem}/index.html"
        row.update({ASPRS_COLOURS.get(int(v), (str(v),))[0]: f"{100 * m / len(k):.1f} %"
                    for v, m in zip(codes, n)})
        rows.append(row)
    facts = {"input": str(args.input), "output": str(args.output), "tiles": len(cat),
             "points": cat.n_points, "buffer": buffer, "seconds": round(seconds, 1)}
    params = {k: v for k, v in vars(args).items()
              if not k.startswith("_") and k not in ("func", "input", "output")}
    return write_run_report(folder, title=f"lidarstat {args.command}", facts=facts,
                            params=params, xyz=np.concatenate(xyz),
                            classes=np.concatenate(cls), tiles=rows, links=links,
                            dtm=read_geotiff(mosaic) if mosaic is not None else None)
