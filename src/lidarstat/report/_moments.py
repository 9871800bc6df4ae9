"""Report of a moments classification: JSON, one PNG per analysis, an HTML page."""

from __future__ import annotations

import html
import json
from pathlib import Path

from .._shared._atomic import atomic_path
from ._views import _save, locked

__all__ = ["write_moments_report"]


@locked
def _step_png(path, rec):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a0, a1) = plt.subplots(1, 2, figsize=(11, 3.6), dpi=90)
    de = rec.density
    if de is not None:
        a0.plot(de.grid, de.density, color="k")
        a0.set_title(f"density of {rec.category} (h = {de.bandwidth:.3g}, {de.method})")
        if rec.choice.cycle is not None:
            a0.axvline(rec.choice.threshold, color="r", ls="--", label="cut")
            a0.legend(loc="upper right")
    c = rec.curves
    a1.plot(c["cycle"], c["skewness"], label="skewness", color="tab:blue")
    a1.plot(c["cycle"], c["kurtosis"], label="kurtosis", color="tab:orange")
    if rec.choice.cycle is not None:
        a1.axvline(rec.choice.cycle, color="r", ls="--",
                   label=f"cycle {rec.choice.cycle} ({rec.choice.rule})")
    a1.set_xlabel("removal cycle")
    a1.set_yscale("symlog")
    a1.legend(loc="upper right", fontsize=8)
    dips = ", ".join(f"{k}: dip {v['dip']:.4f}, p {v['pvalue']:.3g}" for k, v in rec.dip.items())
    a1.set_title(f"window {rec.window} step {rec.step}: {rec.population} (n = {rec.n})\n{dips}",
                 fontsize=9)
    # fixed margins: the panels' layout is the same in every picture, and measuring it
    # (tight layout) costs more than drawing them
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.14, top=0.84, wspace=0.15)
    _save(fig, plt, path, tight=False)


def write_moments_report(folder, result, *, input_path=None, output_path=None, seconds=None,
                         max_plots: int = 60) -> Path:
    """Write ``report.json``, ``step_NNN.png`` and ``index.html`` into `folder`.

    Parameters
    ----------
    folder : path-like
        Created if missing.
    result : MomentsClassification
    max_plots : int
        At most this many analyses get a PNG (the JSON lists all of them).

    Returns
    -------
    Path
        The HTML page.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = {"input": str(input_path) if input_path else None,
            "output": str(output_path) if output_path else None, "seconds": seconds,
            "params": result.params, "counts": result.counts(), "windows": result.windows,
            "steps": [s.to_dict() for s in result.steps]}
    with atomic_path(folder / "report.json") as tmp:
        tmp.write_text(json.dumps(meta, indent=1, default=float))
    rows = []
    for i, rec in enumerate(result.steps[:max_plots]):
        name = f"step_{i:03d}.png"
        _step_png(folder / name, rec)
        ch = rec.choice
        rows.append(
            f"<h3>window {html.escape(str(rec.window))}, step {rec.step}: "
            f"{html.escape(rec.population)} by {rec.category}</h3>"
            f"<p>n = {rec.n}; dip tests: {html.escape(json.dumps(rec.dip))}<br>"
            f"cycle {ch.cycle} ({ch.rule}), threshold {ch.threshold:.4g}; evidence: "
            f"{html.escape(json.dumps(ch.evidence, default=float))}</p>"
            f'<img src="{name}" width="900">')
    counts = "".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>"
                     for k, v in result.counts().items())
    page = ("<!doctype html><html><head><meta charset='utf-8'><title>lidarstat moments"
            "</title></head><body><h1>lidarstat moments</h1>"
            f"<p>input: {html.escape(str(input_path))}<br>output: "
            f"{html.escape(str(output_path))}<br>parameters: "
            f"{html.escape(json.dumps(result.params, default=str))}</p>"
            f"<table border=1><tr><th>class</th><th>points</th></tr>{counts}</table>"
            f"<p>{len(result.steps)} analyses; {len(result.windows)} analysis windows (report.json has "
            "all of them)</p>" + "".join(rows) + "</body></html>")
    out = folder / "index.html"
    with atomic_path(out) as tmp:
        tmp.write_text(page)
    return out
