"""What a moments classification gives back: ASPRS codes, the analyses, the windows."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ..errors import LidarstatDeprecationWarning
from ..stats import DensityEstimate, SequentialMoments
from ._cycle import CycleChoice

__all__ = ["ASPRS", "MomentsClassification", "MomentsStep", "curve_step", "thin_curves"]

#: ASPRS LAS classification codes written by ``moments``.
ASPRS = {"unclassified": 1, "ground": 2, "low_vegetation": 3, "medium_vegetation": 4,
         "high_vegetation": 5, "building": 6, "low_noise": 7, "road": 11}

_CURVE_SAMPLES = 600  # samples of each curve kept for the report


def curve_step(cycles: int) -> int:
    """Stride of the samples :func:`thin_curves` keeps of curves of `cycles` cycles."""
    return max(1, cycles // _CURVE_SAMPLES)


def thin_curves(sm: SequentialMoments) -> dict:
    """About 600 samples of each curve, as copies: a strided view would keep the whole
    curve (one value per point analysed) alive in the report records."""
    s = slice(None, None, curve_step(sm.cycle.size))
    return {name: getattr(sm, name)[s].copy()
            for name in ("cycle", "skewness", "kurtosis", "threshold", "remaining")}


@dataclass(frozen=True)
class MomentsStep:
    """One analysed population: what was tested, the curves and the cycle chosen.

    Attributes
    ----------
    window : int or str
        Analysis window: the root window's index for the paper's clustering steps, its
        path (``'3.1.0'``: root 3, quadrant 1, quadrant 0) for a ground cut, -1 for the
        analysis of the whole ground cluster (roads).
    step : int
        Step number inside the window (1 = first category).
    population : str
        What was analysed (``'tile'``, ``'cluster 1'``, ``'unclassified'`` ...).
    category : str
        ``'elevation'`` (height above the ground model) or ``'intensity'``.
    n : int
        Values analysed.
    dip : dict
        Dip statistic, p-value and decision per category tested at this step.
    choice : CycleChoice
        The separating cycle and its evidence.
    curves : dict
        Thinned ``cycle``, ``skewness``, ``kurtosis``, ``threshold`` arrays.
    density : DensityEstimate or None
        Density of the analysed category.
    """

    window: int | str
    step: int
    population: str
    category: str
    n: int
    dip: dict
    choice: CycleChoice
    curves: dict
    density: DensityEstimate | None = None

    def to_dict(self) -> dict:
        """JSON-ready summary (curves excluded)."""
        return {"window": self.window, "step": self.step, "population": self.population,
                "category": self.category, "n": self.n, "dip": self.dip,
                "choice": self.choice.to_dict()}


@dataclass(frozen=True)
class MomentsClassification:
    """Result of :func:`~lidarstat.classify.moments`.

    Attributes
    ----------
    classification : (N,) ndarray of uint8
        ASPRS codes (see :data:`ASPRS`).
    cluster_id : (N,) ndarray of int32
        Cluster each point was assigned to by the moment procedure (unique over windows;
        0 = none).
    height : (N,) ndarray of float64
        Height above the ground surface model.
    ground : (N,) ndarray of bool
        Ground (classes 2 and 11).
    steps : list of MomentsStep
        Every analysis, in order, for the report.
    windows : list of dict
        Analysis windows: boxes, sizes, split decisions and ground cuts.
    params : dict
        Parameters used (after defaults and unit conversion).
    cut : (N,) ndarray of float64
        Height cut of the last pass at each point (ground when ``height <= cut``): the
        window cuts interpolated between the centres of the finest windows; inf where a
        root window found no cut, NaN for low noise.
    tolerance : (N,) ndarray of float64
        Upper bound of the terrain step's test at each point (ground when
        ``height <= tolerance``, within the depth bound below); inf where the terrain
        step did not run, NaN for low noise.
    building_fields : dict
        The building test's values per point (names in
        :data:`~lidarstat.classify.BUILDING_FIELDS`).
    """

    classification: np.ndarray
    cluster_id: np.ndarray
    height: np.ndarray
    ground: np.ndarray
    steps: list = field(default_factory=list)
    windows: list = field(default_factory=list)
    params: dict = field(default_factory=dict)
    cut: np.ndarray | None = None
    tolerance: np.ndarray | None = None
    building_fields: dict = field(default_factory=dict)

    @property
    def tiles(self) -> list:
        """Deprecated name of :attr:`windows`."""
        warnings.warn("MomentsClassification.tiles is deprecated; use windows",
                      LidarstatDeprecationWarning, stacklevel=2)
        return self.windows

    def to_fields(self) -> dict:
        """Per-point output fields: ``classification``, ``cluster_id`` and the building
        test's values (:data:`~lidarstat.classify.BUILDING_FIELDS`)."""
        return {"classification": self.classification, "cluster_id": self.cluster_id,
                **self.building_fields}

    def counts(self) -> dict:
        """Points per ASPRS class name."""
        names = {v: k for k, v in ASPRS.items()}
        codes, n = np.unique(self.classification, return_counts=True)
        return {names.get(int(c), str(int(c))): int(k) for c, k in zip(codes, n)}

    def summary(self) -> str:
        """A few lines for the terminal."""
        tot = max(1, self.classification.size)
        lines = [(f"{self.classification.size} points, {len(self.windows)} analysis "
                  f"windows, {len(self.steps)} moment analyses")]
        for name, k in self.counts().items():
            lines.append(f"  {name:<18}{k:>10}  {100 * k / tot:5.1f} %")
        return "\n".join(lines)
