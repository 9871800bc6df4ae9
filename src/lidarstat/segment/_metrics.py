"""Scores of a segmentation against the truth (Hoover et al. 1996) and binary F1."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._shared._deprecate import renamed_parameters
from ..errors import InvalidParameterError


@dataclass
class HooverScore:
    """Hoover et al. (1996) region classification of a segmentation.

    Attributes
    ----------
    tolerance : float
        The overlap tolerance T (0.5 < T <= 1).
    n_truth, n_pred : int
        Truth regions scored (at least `min_points` points) and machine segments.
    correct, over, under, missed, noise : int
        Truth regions correctly detected, over-segmented, under-segmented (counted as
        truth regions), missed, and machine segments that are noise.
    correct_pairs : (C, 2) ndarray
        (truth id, machine id) of each correct detection.
    over_segmented, under_segmented : dict
        truth id -> machine ids; machine id -> truth ids.
    missed_ids, noise_ids : ndarray
    """

    tolerance: float
    n_truth: int
    n_pred: int
    correct: int
    over: int
    under: int
    missed: int
    noise: int
    correct_pairs: np.ndarray
    over_segmented: dict = field(default_factory=dict)
    under_segmented: dict = field(default_factory=dict)
    missed_ids: np.ndarray = field(default_factory=lambda: np.empty(0, int))
    noise_ids: np.ndarray = field(default_factory=lambda: np.empty(0, int))

    @property
    def correct_rate(self) -> float:
        """Share of truth regions correctly detected."""
        return self.correct / self.n_truth if self.n_truth else float("nan")

    def as_dict(self) -> dict:
        """The counts and the correct-detection rate."""
        return {"tolerance": self.tolerance, "n_truth": self.n_truth, "n_pred": self.n_pred,
                "correct": self.correct, "over": self.over, "under": self.under,
                "missed": self.missed, "noise": self.noise,
                "correct_rate": self.correct_rate}

    def summary(self) -> str:
        """One line."""
        return (f"Hoover T={self.tolerance}: {self.correct}/{self.n_truth} correct "
                f"({100 * self.correct_rate:.1f}%), {self.over} over, {self.under} under, "
                f"{self.missed} missed, {self.noise} noise ({self.n_pred} segments)")


@renamed_parameters(min_size="min_points")
def hoover(pred, truth, tolerance: float = 0.8, *, min_points: int = 0) -> HooverScore:
    """Compare a segmentation with the truth by Hoover et al.'s five region classes.

    With M_m points in truth region m, N_n in machine segment n and O_mn in both:

    - correct detection: O_mn >= T M_m and O_mn >= T N_n;
    - over-segmentation: truth region m and machine segments n_1..n_x (x >= 2), each
      O >= T N_ni, together sum O >= T M_m;
    - under-segmentation: machine segment n and truth regions m_1..m_x (x >= 2), each
      O >= T M_mi, together sum O >= T N_n;
    - missed: a truth region in none of these; noise: a machine segment in none.

    Classes are assigned in that order (correct first). Label 0 means "no region" in both
    inputs; a machine segment's size N_n counts all its points, including those on no
    truth region (clutter assigned to a plane counts against it).

    Parameters
    ----------
    pred, truth : (N,) array of int
        Machine segment and true region per point.
    tolerance : float, default 0.8
        T, in (0.5, 1].
    min_points : int, default 0
        Truth regions with fewer points are not scored (and machine segments lying mainly
        on them are neither noise nor scored).

    Returns
    -------
    HooverScore

    Examples
    --------
    >>> truth = np.array([1, 1, 1, 1, 2, 2, 2, 2, 3, 3])
    >>> pred = np.array([5, 5, 5, 5, 6, 6, 7, 7, 8, 8])
    >>> s = hoover(pred, truth, 0.8)
    >>> s.correct, s.over, s.missed, s.noise
    (2, 1, 0, 0)
    """
    pred = np.asarray(pred)
    truth = np.asarray(truth)
    if pred.shape != truth.shape or pred.ndim != 1:
        raise InvalidParameterError(
            f"pred and truth must be 1-D of equal length, got {pred.shape} and {truth.shape}")
    t = float(tolerance)
    if not 0.5 < t <= 1.0:
        raise InvalidParameterError(f"tolerance must be in (0.5, 1], got {tolerance}")
    p_ids, p_inv, p_size = np.unique(pred, return_inverse=True, return_counts=True)
    t_ids, t_inv, t_size = np.unique(truth, return_inverse=True, return_counts=True)
    both = (pred > 0) & (truth > 0)
    key = t_inv[both].astype(np.int64) * p_ids.size + p_inv[both]
    k, o = np.unique(key, return_counts=True)
    pm, pn = k // p_ids.size, k % p_ids.size  # indices into t_ids, p_ids
    M = t_size[pm].astype(float)
    N = p_size[pn].astype(float)
    scored_t = (t_ids > 0) & (t_size >= min_points)
    # Machine segments whose largest overlap is with an unscored truth region are left out.
    best_t = np.full(p_ids.size, -1)
    best_o = np.zeros(p_ids.size)
    order = np.argsort(o, kind="stable")
    best_t[pn[order]] = pm[order]
    best_o[pn[order]] = o[order]
    scored_p = (p_ids > 0) & ~((best_t >= 0) & ~scored_t[np.maximum(best_t, 0)])
    ok_pair = scored_t[pm] & scored_p[pn]
    used_t = np.zeros(t_ids.size, bool)
    used_p = np.zeros(p_ids.size, bool)

    corr = ok_pair & (o >= t * M) & (o >= t * N)
    used_t[pm[corr]] = True
    used_p[pn[corr]] = True
    correct_pairs = np.c_[t_ids[pm[corr]], p_ids[pn[corr]]]

    over, under = {}, {}
    cand = ok_pair & ~used_t[pm] & ~used_p[pn] & (o >= t * N)
    for m in np.unique(pm[cand]):
        sel = cand & (pm == m)
        if sel.sum() >= 2 and o[sel].sum() >= t * t_size[m]:
            over[t_ids[m].item()] = p_ids[pn[sel]].tolist()
            used_t[m] = True
            used_p[pn[sel]] = True
    cand = ok_pair & ~used_t[pm] & ~used_p[pn] & (o >= t * M)
    for n in np.unique(pn[cand]):
        sel = cand & (pn == n)
        if sel.sum() >= 2 and o[sel].sum() >= t * p_size[n]:
            under[p_ids[n].item()] = t_ids[pm[sel]].tolist()
            used_p[n] = True
            used_t[pm[sel]] = True
    n_under_truth = sum(len(v) for v in under.values())
    missed = t_ids[scored_t & ~used_t]
    noise = p_ids[scored_p & ~used_p]
    return HooverScore(tolerance=t, n_truth=int(scored_t.sum()), n_pred=int(scored_p.sum()),
                       correct=int(corr.sum()), over=len(over), under=n_under_truth,
                       missed=int(missed.size), noise=int(noise.size),
                       correct_pairs=correct_pairs, over_segmented=over,
                       under_segmented=under, missed_ids=missed, noise_ids=noise)


def binary_scores(pred, truth) -> dict[str, float]:
    """Precision, recall and F1 of a binary labelling (e.g. edge points) against truth.

    Examples
    --------
    >>> binary_scores([1, 1, 0, 0], [1, 0, 1, 0])["f1"]
    0.5
    """
    p = np.asarray(pred).astype(bool)
    g = np.asarray(truth).astype(bool)
    if p.shape != g.shape:
        raise InvalidParameterError(f"pred and truth shapes differ: {p.shape} vs {g.shape}")
    tp = int(np.count_nonzero(p & g))
    fp = int(np.count_nonzero(p & ~g))
    fn = int(np.count_nonzero(~p & g))
    prec = tp / (tp + fp) if tp + fp else float("nan")
    rec = tp / (tp + fn) if tp + fn else float("nan")
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else float("nan")
    return {"precision": prec, "recall": rec, "f1": f1, "tp": tp, "fp": fp, "fn": fn}


@dataclass
class CreaseCoverage:
    """How much of the true crease length a set of detected points covers.

    Attributes
    ----------
    length : float
        Visible length of the true creases (both adjacent faces sampled near it).
    covered : float
        Part of that length with a detected point within the tolerance.
    ratio : float
        ``covered / length`` (NaN when nothing is visible).
    per_crease : list of dict
        ``faces``, ``convex``, ``length``, ``covered`` of each crease with a visible part.
    tolerance : float
    """

    length: float
    covered: float
    ratio: float
    per_crease: list
    tolerance: float


def crease_coverage(creases, detected, tolerance, *, points=None, faces=None,
                    visible_distance=None, step=None) -> CreaseCoverage:
    """Share of the true crease length that has a detected point within `tolerance`.

    The creases (``lidarstat.synth.crease_lines`` dicts: segments or arcs) are sampled every
    `step` (default ``tolerance / 4``); a sample is *visible* when each of the two faces
    meeting there has a point of the cloud (`points` with face ids `faces`) within
    `visible_distance` (default twice the tolerance), so that occluded or unscanned parts
    of a crease do not count; without `points` every sample counts. A visible sample is
    covered when a point of `detected` lies within `tolerance` (3-D).

    Parameters
    ----------
    creases : list of dict
    detected : (M, 3) array_like
        Positions of the detected edge (ridge, barrier) points.
    tolerance : float
    points : (N, 3) array_like, optional
        The cloud (true positions preferably), for the visibility test.
    faces : (N,) array_like of int, optional
        Face id (as in ``creases[i]["faces"]``) of every point of `points`.
    visible_distance, step : float, optional

    Returns
    -------
    CreaseCoverage

    Examples
    --------
    >>> import numpy as np
    >>> line = [{"kind": "segment", "faces": (0, 1), "convex": True,
    ...          "vertices": np.array([[0.0, 0, 0], [1.0, 0, 0]])}]
    >>> det = np.c_[np.linspace(0, 0.5, 51), np.zeros(51), np.full(51, 0.01)]
    >>> print(f"{crease_coverage(line, det, 0.02).ratio:.3f}")  # half the line, plus the tolerance
    0.515
    """
    from scipy.spatial import cKDTree

    tolerance = float(tolerance)
    if not tolerance > 0:
        raise InvalidParameterError(f"crease_coverage: tolerance must be > 0, got {tolerance}")
    step = tolerance / 4.0 if step is None else float(step)
    visible_distance = 2.0 * tolerance if visible_distance is None else float(visible_distance)
    det = np.asarray(detected, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(det) if det.shape[0] else None
    face_trees = {}
    if points is not None:
        if faces is None:
            raise InvalidParameterError("crease_coverage: `points` needs `faces`")
        pts = np.asarray(points, dtype=np.float64)
        faces = np.asarray(faces)
        for f in np.unique(faces):
            face_trees[int(f)] = cKDTree(pts[faces == f])
    total = covered = 0.0
    rows = []
    for cr in creases:
        v = np.asarray(cr["vertices"], dtype=np.float64)
        seg = np.linalg.norm(np.diff(v, axis=0), axis=1)
        cum = np.r_[0.0, np.cumsum(seg)]
        if cum[-1] <= 0:
            continue
        s = np.arange(0.5 * step, cum[-1], step)
        samples = np.column_stack([np.interp(s, cum, v[:, c]) for c in range(3)])
        w = np.full(s.size, step)
        w[-1] = cum[-1] - s[-1] + 0.5 * step
        vis = np.ones(s.size, bool)
        if points is not None:
            for f in cr["faces"]:
                t = face_trees.get(int(f))
                if t is None:
                    vis[:] = False
                    break
                d, _ = t.query(samples, k=1, distance_upper_bound=visible_distance)
                vis &= np.isfinite(d)
        if not vis.any():
            continue
        hit = np.zeros(s.size, bool)
        if tree is not None:
            d, _ = tree.query(samples[vis], k=1, distance_upper_bound=tolerance)
            hit[vis] = np.isfinite(d)
        length = float(w[vis].sum())
        cov = float(w[hit].sum())
        rows.append({"faces": tuple(int(f) for f in cr["faces"]), "convex": bool(cr["convex"]),
                     "length": length, "covered": cov})
        total += length
        covered += cov
    return CreaseCoverage(length=total, covered=covered,
                          ratio=covered / total if total > 0 else float("nan"),
                          per_crease=rows, tolerance=tolerance)
