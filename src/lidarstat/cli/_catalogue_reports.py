"""``--report DIR`` of ``curvature``, ``covariance``, ``ridges`` and ``segment``.

The page has the structure of the ``moments`` report (:func:`lidarstat.report.
write_run_report`): the run, a plan-view map of the classes (or segments) the command
wrote, its fields on maps, the outcomes of its tests, and maps of where the tests were
not significant. The report reads the command's output back, so it shows what the file
holds; with a catalogue there is one page per tile (``DIR/tiles/<tile>/``) and one page
for the area (``DIR/index.html``) linking to them.

A command's report is described by a function ``(args, fields) -> dict`` of the keyword
arguments of ``write_run_report`` (``classes``, ``class_names``, ``class_field``,
``values``, ``flags``, ``tests``, ``segments``) and the fields it reads (:data:`REPORTS`).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["REPORTS", "write_area_report", "write_report"]

#: At most this many points are drawn on the maps of one page (a regular subsample).
MAP_POINTS = 1_500_000


def _surface_type_names():
    from ..features import SurfaceType

    colours = ["#bdbdbd", "#90caf9", "#ef6c00", "#1565c0", "#c62828", "#6a1b9a", "#f9a825",
               "#00897b", "#5d4037"]
    return {int(t): (t.name.lower().replace("_", " "), colours[int(t)]) for t in SurfaceType}


def _outcomes(name, tested, rejected):
    import numpy as np

    tested = np.asarray(tested, bool)
    rejected = np.asarray(rejected, bool) & tested
    return (name, int(rejected.sum()), int((tested & ~rejected).sum()),
            int((~tested).sum()))


def _curvature(args, f):
    import numpy as np

    tested = f["status"] == 0
    fitted = np.isin(f["status"], (0, 3))  # 1: too few neighbours, 2: degenerate
    return dict(
        classes=f["surface_type"], class_names=_surface_type_names(),
        class_field="surface_type",
        values={"mean curvature H (signed)": f["H"], "Gaussian curvature K (signed)": f["K"]},
        tests=[_outcomes("quadric chi-square", fitted, f["status"] == 3),
               _outcomes("K = 0", tested, f["K_sig"] == 1),
               _outcomes("H = 0", tested, f["H_sig"] == 1)],
        flags={"H not significant (H = 0 kept)": tested & (f["H_sig"] == 0),
               "no tested quadric (few neighbours, degenerate or rejected fit)": ~tested})


_COVARIANCE_CLASSES = {0: ("undetermined", "#9e9e9e"), 1: ("surface", "#90caf9"),
                       2: ("edge", "#e53935"), 3: ("boundary", "#fb8c00")}


def _covariance(args, f):
    import numpy as np

    pc = f["point_class"]
    plane = np.isfinite(f["plane_p"])
    bnd = np.isfinite(f["boundary_p"])
    flat = plane & (f["plane_p"] >= args.alpha)
    return dict(
        classes=pc, class_names=_COVARIANCE_CLASSES, class_field="point_class",
        values={"surface variation": f["SurfaceVariation"], "planarity": f["Planarity"]},
        tests=[_outcomes("plane (low curvature)", plane, f["plane_p"] < args.alpha),
               _outcomes("boundary", bnd, pc == 3)],
        flags={"plane test not significant (a plane)": flat,
               "no tested neighbourhood (undetermined)": pc == 0})


_RIDGE_CLASSES = {0: ("none", "#e0e0e0"), 1: ("crest", "#c62828"), 2: ("ravine", "#1565c0"),
                  3: ("crease", "#2e7d32")}


def _ridges(args, f):
    fitted = f["status"] == 0
    return dict(
        classes=f["ridge"], class_names=_RIDGE_CLASSES, class_field="ridge",
        values={"k1 (signed)": f["k1"], "k2 (signed)": f["k2"]},
        tests=[_outcomes("jet chi-square", fitted, f["chi2_pass"] == 0),
               _outcomes("umbilic (k1 = k2)", fitted, f["umbilic"] == 0)],
        flags={"k1 - k2 not significant (umbilic)": fitted & (f["umbilic"] == 1),
               "jet rejected by its chi-square test": fitted & (f["chi2_pass"] == 0)})


def _segment(args, f):
    ids = f["segment_id"]
    return dict(classes=ids, class_field="segment_id", segments=True,
                flags={"in no segment": ids == 0})


#: command -> (fields the report reads, the function describing the page).
REPORTS = {
    "curvature": (("surface_type", "status", "H", "K", "H_sig", "K_sig"), _curvature),
    "covariance": (("point_class", "plane_p", "boundary_p", "SurfaceVariation",
                    "Planarity"), _covariance),
    "ridges": (("ridge", "k1", "k2", "status", "chi2_pass", "umbilic"), _ridges),
    "segment": (("segment_id",), _segment),
}


def _title(args):
    what = f" --method {args.method}" if getattr(args, "method", None) else ""
    return f"lidarstat {args.command}{what}"


def _params(args):
    return {k: v for k, v in vars(args).items()
            if not k.startswith("_") and k not in ("func", "input", "output")}


def _read(paths, names, step=1):
    import numpy as np

    from ..io import read

    xyz, fields = [], {n: [] for n in names}
    for p in paths:
        c = read(p, fields=list(names))
        xyz.append(c.xyz[::step])
        for n in names:
            fields[n].append(np.asarray(c.attributes[n])[::step])
    return np.concatenate(xyz), {n: np.concatenate(v) for n, v in fields.items()}


def write_report(folder, args, output, *, facts=None, seconds=None) -> Path:
    """The report of one output file (a single run, or one tile of a catalogue)."""
    from ..report import write_run_report

    names, describe = REPORTS[args.command]
    xyz, f = _read([output], names)
    n = len(xyz)
    step = max(1, -(-n // MAP_POINTS))
    xyz, f = xyz[::step], {k: v[::step] for k, v in f.items()}
    facts = facts or {"input": str(args.input), "output": str(output), "points": n}
    if seconds is not None:
        facts["seconds"] = round(seconds, 1)
    return write_run_report(folder, title=_title(args), facts=facts, params=_params(args),
                            xyz=xyz, **describe(args, f))


def write_area_report(folder, args, cat, runs, buffer, seconds) -> Path:
    """One page for a catalogue (every tile on the maps, shares per tile) and one page per
    tile behind a link."""
    import numpy as np

    from ..report import write_run_report

    folder = Path(folder)
    names, describe = REPORTS[args.command]
    step = max(1, -(-cat.n_points // MAP_POINTS))
    xyz, f = _read([r.output for r in runs], names, step)
    spec = describe(args, f)
    rows, links = [], {}
    for r in runs:
        page = write_report(folder / "tiles" / r.output.stem, args, r.output,
                            facts={"tile": str(r.input), "output": str(r.output),
                                   "points": r.n_points, "buffer points": r.n_buffer})
        links[f"{r.input.name}: tile page"] = page.relative_to(folder).as_posix()
        _, tf = _read([r.output], names[:1])
        row = {"tile": r.input.name, "points": len(tf[names[0]])}
        if spec.get("segments"):
            ids = tf[names[0]]
            row.update({"segments": int(np.unique(ids[ids > 0]).size),
                        "in a segment": f"{100 * np.mean(ids > 0):.1f} %"})
        else:
            codes, counts = np.unique(tf[names[0]], return_counts=True)
            cn = spec["class_names"]
            row.update({cn.get(int(v), (str(v),))[0]: f"{100 * c / max(counts.sum(), 1):.1f} %"
                        for v, c in zip(codes, counts)})
        rows.append(row)
    facts = {"input": str(args.input), "output": str(args.output), "tiles": len(cat),
             "points": cat.n_points, "buffer": buffer, "seconds": round(seconds, 1)}
    return write_run_report(folder, title=_title(args), facts=facts, params=_params(args),
                            xyz=xyz, tiles=rows, links=links, **spec)
