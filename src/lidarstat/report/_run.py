"""The report of one run (one file or a catalogue of tiles): :func:`write_run_report`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._maps import (
    ASPRS_COLOURS,
    plot_class_map,
    plot_flag_map,
    plot_hillshade,
    plot_segment_map,
    plot_value_map,
)
from ._page import ReportPage

__all__ = ["map_resolution", "write_run_report"]


def map_resolution(xyz, *, cells: int = 600) -> float:
    """A cell size for plan-view maps: about `cells` cells along the longer side, and at
    least twice the mean point spacing (so that cells are not mostly empty), rounded to
    1, 2, 2.5 or 5 times a power of ten."""
    xy = np.asarray(xyz)[:, :2]
    span = np.ptp(xy, axis=0) if len(xy) else np.ones(2)
    spacing = math.sqrt(max(float(span[0] * span[1]), 1e-12) / max(len(xy), 1))
    raw = max(float(span.max()) / cells, 2.0 * spacing, 1e-6)
    step = 10 ** math.floor(math.log10(raw))
    return float(min((m * step for m in (1, 2, 2.5, 5, 10) if m * step >= raw),
                     default=10 * step))


def write_run_report(folder, *, title: str, facts: dict, params: dict, xyz, classes,
                     class_names: dict | None = None, class_field: str = "classification",
                     dtm=None, tiles: list[dict] | None = None,
                     flags: dict | None = None, links: dict | None = None,
                     resolution: float | None = None, values: dict | None = None,
                     segments: bool = False, tests: list | None = None) -> Path:
    """Write the HTML report of a run into `folder`; the path of ``index.html``.

    Parameters
    ----------
    folder : path-like
        Created if missing; the page and its PNGs go there.
    title : str
        E.g. ``"lidarstat moments"``.
    facts : dict
        Inputs, outputs, points, seconds: shown as a table.
    params : dict
        The parameters used (``result.params``).
    xyz : ndarray, shape (N, 3)
        The points (all tiles of a catalogue, or a subsample of them).
    classes : ndarray, shape (N,)
        The class each point got (ASPRS codes, or the method's own with `class_names`).
    class_names : dict of int to (name, colour), optional
        Default: ASPRS names and colours.
    class_field : str
        Name of the field the classes are written to (said in the caption).
    dtm : Raster, optional
        Terrain model: a hillshade is shown.
    tiles : list of dict, optional
        One row per tile: ``{"tile": name, "points": n, <class name>: share, ...}``.
    flags : dict of str to bool ndarray, optional
        Per-point flags mapped as shares per cell, e.g. ``{"tests not significant": m}``.
    links : dict of str to str, optional
        Text -> relative href (per-tile plots).
    resolution : float, optional
        Cell size of the maps (default: about 600 cells along the longer side).
    values : dict of str to (N,) ndarray, optional
        Fields shown on a map as their median per cell (label -> values; a label ending
        in ``" (signed)"`` gets a colour scale symmetric about 0).
    segments : bool
        `classes` are segment ids (0: in no segment): each segment in a colour of its own,
        the table lists the largest segments.
    tests : list of (name, rejected, not significant, not tested), optional
        Outcomes of the method's tests, as a table (point counts).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    xyz = np.asarray(xyz, dtype=np.float64)
    classes = np.asarray(classes)
    names = ASPRS_COLOURS if class_names is None else class_names
    res = map_resolution(xyz) if resolution is None else resolution
    page = ReportPage(title, subtitle=" · ".join(str(v) for v in list(facts.values())[:2]))
    page.section("Run")
    page.facts(facts)
    page.parameters(params)
    if segments:
        _segments(page, folder, xyz, classes, res, class_field)
    else:
        page.section("Classes", f"The class of the topmost point in each {res:g} x {res:g} "
                     "cell, as the area looks from above.")
        plot_class_map(folder / "classes.png", xyz, classes, resolution=res,
                       title=f"{class_field} (plan view)", names=names)
        page.figure("classes.png", f"{class_field}: plan view, cells of {res:g}")
        codes, counts = np.unique(classes, return_counts=True)
        page.table(["class", "points", "share"],
                   [[f"{int(v)} {names.get(int(v), (str(v),))[0]}", int(c),
                     f"{100 * c / len(classes):.2f} %"] for v, c in zip(codes, counts)])
    if dtm is not None:
        page.section("Terrain model", f"Hillshade of the ground surface at "
                     f"{dtm.resolution:g} resolution.")
        plot_hillshade(folder / "terrain.png", dtm)
        page.figure("terrain.png", "terrain model: hillshade, heights in colour")
    if tiles:
        page.section("Tiles", "Share of each class per tile.")
        columns = list(dict.fromkeys(k for row in tiles for k in row))
        page.table(columns, [[row.get(c, "") for c in columns] for row in tiles])
    for i, (label, v) in enumerate((values or {}).items()):
        if i == 0:
            page.section("Fields", "Median of each field per cell.")
        name = f"field_{i}.png"
        plot_value_map(folder / name, xyz, v, resolution=res * 2, title=label,
                       symmetric=label.endswith("(signed)"))
        page.figure(name, f"{label}: median per {2 * res:g} cell")
    if tests:
        page.section("Tests", "Points per outcome of each test.")
        page.table(["test", "rejected", "not significant", "not tested"],
                   [list(row) for row in tests])
    for i, (label, mask) in enumerate((flags or {}).items()):
        if i == 0:
            page.section("Where the tests were not significant")
        name = f"flags_{i}.png"
        plot_flag_map(folder / name, xyz, mask, resolution=res * 4, title=label)
        page.figure(name, f"{label}: share of the points per cell "
                    f"({int(np.count_nonzero(mask))} of {len(mask)} points)")
    if links:
        page.section("More")
        for text, href in links.items():
            page.link(href, text)
    return page.write(folder)


def _segments(page, folder, xyz, labels, res, field):
    """The segments section: a map in colours per segment and the largest segments."""
    page.section("Segments", f"The segment of the topmost point in each {res:g} x {res:g} "
                 "cell; grey: in no segment.")
    plot_segment_map(folder / "classes.png", xyz, labels, resolution=res,
                     title=f"{field} (plan view)")
    page.figure("classes.png", f"{field}: plan view, cells of {res:g}")
    ids, counts = np.unique(np.asarray(labels, dtype=np.int64), return_counts=True)
    inside = ids > 0
    n = max(len(labels), 1)
    rows = [["segments", int(inside.sum()), ""],
            ["points in a segment", int(counts[inside].sum()),
             f"{100 * counts[inside].sum() / n:.2f} %"],
            ["points in none", int(counts[~inside].sum()),
             f"{100 * counts[~inside].sum() / n:.2f} %"]]
    top = np.argsort(counts[inside])[::-1][:10]
    rows += [[f"segment {int(ids[inside][j])}", int(counts[inside][j]),
              f"{100 * counts[inside][j] / n:.2f} %"] for j in top]
    page.table(["", "points", "share"], rows)
