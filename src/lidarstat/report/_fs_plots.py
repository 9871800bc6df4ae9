"""Forward Search monitoring plots: deletion residual and F statistic against subset size."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._shared._atomic import atomic_path


def plot_forward_search(res, path, *, title=None):
    """Two panels: smallest deletion residual with its envelope, and the F statistics.

    Parameters
    ----------
    res : ForwardSearchResult
        Result of :func:`lidarstat.segment.forward_search`.
    path : str or Path
        PNG written atomically.
    title : str, optional
        Figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 6), dpi=100, sharex=True)
    m = res.msize
    m_before = np.concatenate(([res.m0], m[:-1])) if m.size else m
    a1.plot(m_before, res.rmin, lw=1, label="min deletion residual")
    a1.plot(m_before, res.envelope, "r--", lw=1, label="envelope")
    a1.set_ylabel("standardised residual")
    a1.legend(loc="upper left", fontsize=8)
    with np.errstate(divide="ignore"):
        a2.plot(m, res.fstat, lw=1, label="F (difference covariance)")
        a2.plot(m, res.fpaper, lw=1, alpha=0.7, label="F as printed in the paper")
    a2.set_yscale("log")
    a2.set_ylabel("F statistic")
    a2.set_xlabel("subset size m")
    a2.legend(loc="upper left", fontsize=8)
    for ax in (a1, a2):
        ax.axvline(res.m, color="k", lw=0.8, ls=":")
    fig.suptitle(title or f"Forward Search: n_s={res.m0}, m={res.m}, stop: {res.stop_reason}")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)


def plot_forward_search_units(folder, units, *, limit: int = 40) -> None:
    """Monitoring plots ``fs_NNNN.png`` of the Forward Search of the first `limit` units.

    Parameters
    ----------
    folder : str or Path
        Created if missing.
    units : sequence of SurfaceUnit
        Refined units in segment order (``Segmentation.units`` of
        :func:`lidarstat.segment.segment_sar`), segment ``s`` is ``units[s - 1]``.
    limit : int, optional
        At most this many plots.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    for s, unit in enumerate(units[:limit], start=1):
        plot_forward_search(unit.fs, folder / f"fs_{s:04d}.png",
                            title=f"segment {s}: n_s={unit.n_s}, n_sa={unit.n_sa}, m={unit.m}, "
                                  f"stop: {unit.fs.stop_reason}")
