"""The result of :func:`covariance_features`: its fields (under PDAL's names), the point
classes, the eigen-feature modes and :func:`eigen_features`, the eigen features of given
eigenvalues."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from .._shared.validation import check_option
from ..io import register_field_descriptions
from ..neighbors import Neighborhoods


class EigenMode(str, enum.Enum):
    """What the eigen features' ratios are computed from (PDAL's ``mode``,
    ``--eigen-mode``)."""

    #: The eigenvalues (jakteristics, CloudCompare).
    RAW = "raw"
    #: Their square roots (PDAL's default, pgeof).
    SQRT = "sqrt"
    #: The eigenvalues divided by their sum.
    NORMALIZED = "normalized"

    def __str__(self):
        return self.value


EIGEN_MODES = tuple(m.value for m in EigenMode)

#: Per-point output fields, name -> (dtype, description). Names follow PDAL's
#: ``filters.covariancefeatures`` / ``filters.normal`` / ``filters.eigenvalues``.
FIELDS = {
    "NormalX": ("float64", "unit normal x (toward the sensor, else up)"),
    "NormalY": ("float64", "unit normal y"),
    "NormalZ": ("float64", "unit normal z"),
    "Eigenvalue0": ("float64", "smallest covariance eigenvalue"),
    "Eigenvalue1": ("float64", "middle covariance eigenvalue"),
    "Eigenvalue2": ("float64", "largest covariance eigenvalue"),
    "SurfaceVariation": ("float64", "lambda0/(lambda0+lambda1+lambda2), eq. 4"),
    "CurvatureVariance": ("float64", "variance of SurfaceVariation over nbhd, eq. 5"),
    "Linearity": ("float64", "(l2-l1)/l2"),
    "Planarity": ("float64", "(l1-l0)/l2"),
    "Scattering": ("float64", "l0/l2"),
    "Verticality": ("float64", "z of the eigenvalue-weighted |e| (PDAL)"),
    "Omnivariance": ("float64", "cbrt(l0 l1 l2)"),
    "Anisotropy": ("float64", "(l2-l0)/l2"),
    "Eigenentropy": ("float64", "-sum l ln l"),
    "EigenvalueSum": ("float64", "l0+l1+l2"),
    "DemantkeVerticality": ("float64", "1-|NormalZ|"),
    "PrincipalDirX": ("float64", "max-curvature direction x (normals)"),
    "PrincipalDirY": ("float64", "max-curvature direction y"),
    "PrincipalDirZ": ("float64", "max-curvature direction z"),
    "NormalVariation": ("float64", "variance of normals along PrincipalDir"),
    "neighbors": ("int32", "points in the neighbourhood"),
}
#: Fields of the automatic scale (PDAL's ``filters.optimalneighborhood`` names).
SCALE_FIELDS = {
    "OptimalKNN": ("int32", "neighbourhood size of minimum eigenentropy"),
    "OptimalRadius": ("float64", "distance to the OptimalKNN-th nearest point"),
}
FIELDS.update(SCALE_FIELDS)
register_field_descriptions(FIELDS)


class PointClass(IntEnum):
    """Codes of ``point_class`` (:func:`lidarstat.classify.covariance`; a contract)."""

    UNDETERMINED = 0
    SURFACE = 1
    EDGE = 2
    BOUNDARY = 3


@dataclass(frozen=True)
class CovarianceResult:
    """Per-point covariance features and what the classification needs beside them.

    Attributes
    ----------
    fields : dict of str -> (N,) ndarray
        The per-point output fields (``FIELDS``), in input order.
    centroid : (N, 3) ndarray
        Neighbourhood centroids (file coordinates).
    major : (N, 3) ndarray
        Eigenvector of the largest eigenvalue.
    offset_uv : (N, 2) ndarray
        Index point minus centroid along the largest and the middle eigenvector (eq. 7, 8).
    mean_variation : (N,) ndarray
        Mean of SurfaceVariation over each neighbourhood (beside its variance, eq. 5).
    k, radius : int or None, float or None
        The neighbourhood definition.
    neighborhoods : Neighborhoods or None
        The neighbourhoods (original indices, rows sorted by distance for kNN), when
        ``keep_neighbors`` was asked.
    sensor : (3,) ndarray or None
        Scanner position, when given.
    ray_range, ray_cos : (N,) ndarray or None
        With a sensor: distance from it and |cos| of the angle between the ray and the
        normal (the share of range noise that falls across the surface).
    scan_boundary : (N, 4) ndarray or None
        With a sensor: Hotelling T2 of the complete-disc centroid in linearised scan
        coordinates, the disc's point count m, its radius over the neighbourhood's and the
        neighbourhood's reach (:mod:`lidarstat.features._scan_kernels`; the reach is the
        scale of the ``'grid'`` boundary test).
    """

    fields: dict
    centroid: np.ndarray
    major: np.ndarray
    offset_uv: np.ndarray
    mean_variation: np.ndarray
    k: int | None
    radius: float | None
    eigen_mode: str = "raw"
    neighborhoods: Neighborhoods | None = None
    sensor: np.ndarray | None = None
    ray_range: np.ndarray | None = None
    ray_cos: np.ndarray | None = None
    scan_boundary: np.ndarray | None = None
    meta: dict = field(default_factory=dict)

    def __getitem__(self, name):
        return self.fields[name]

    def __len__(self):
        return self.fields["SurfaceVariation"].size

    @property
    def normals(self) -> np.ndarray:
        """(N, 3) unit normals."""
        f = self.fields
        return np.stack([f["NormalX"], f["NormalY"], f["NormalZ"]], axis=1)

    @property
    def eigenvalues(self) -> np.ndarray:
        """(N, 3) eigenvalues, ascending."""
        f = self.fields
        return np.stack([f["Eigenvalue0"], f["Eigenvalue1"], f["Eigenvalue2"]], axis=1)

    @property
    def counts(self) -> np.ndarray:
        """Neighbours per point."""
        return self.fields["neighbors"]

    def to_fields(self):
        """The per-point arrays with their file dtypes, for :func:`lidarstat.io.write`."""
        return {k: np.asarray(v, dtype=FIELDS[k][0]) for k, v in self.fields.items()}


def eigen_features(evals, normal, major, *, mode="raw"):
    """The eigenvalue features of PDAL's ``filters.covariancefeatures`` from eigenvalues.

    Parameters
    ----------
    evals : (N, 3) ndarray
        Eigenvalues in ascending order ``l0 <= l1 <= l2`` (``l0`` is the paper's lambda0).
    normal, major : (N, 3) ndarray
        Eigenvectors of ``l0`` and ``l2`` (the middle one is their cross product).
    mode : EigenMode or {'raw', 'sqrt', 'normalized'}
        What the ratios are computed from, as PDAL's ``mode`` option: the eigenvalues
        (jakteristics, CloudCompare), their square roots (PDAL's default, pgeof,
        Guinard and Landrieu 2017) or the eigenvalues divided by their sum.
        ``SurfaceVariation`` and ``EigenvalueSum`` always use the raw eigenvalues (eq. 4).

    Returns
    -------
    dict of str -> (N,) ndarray
    """
    mode = EigenMode(check_option(mode, "mode", EIGEN_MODES, func="eigen_features")).value
    raw = np.asarray(evals, dtype=np.float64)
    total = raw.sum(axis=1)
    if mode == "sqrt":
        lam = np.sqrt(raw)
    elif mode == "normalized":
        with np.errstate(invalid="ignore", divide="ignore"):
            lam = raw / total[:, None]
    else:
        lam = raw
    l0, l1, l2 = lam[:, 0], lam[:, 1], lam[:, 2]
    middle = np.cross(normal, major)
    unary = (l2[:, None] * np.abs(major) + l1[:, None] * np.abs(middle)
             + l0[:, None] * np.abs(normal))
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {
            "Linearity": (l2 - l1) / l2,
            "Planarity": (l1 - l0) / l2,
            "Scattering": l0 / l2,
            "Verticality": unary[:, 2] / np.linalg.norm(unary, axis=1),
            "Omnivariance": np.cbrt(l0 * l1 * l2),
            "Anisotropy": (l2 - l0) / l2,
            "Eigenentropy": -(_xlogx(l0) + _xlogx(l1) + _xlogx(l2)),
            "EigenvalueSum": total,
            "SurfaceVariation": raw[:, 0] / total,
            "DemantkeVerticality": 1.0 - np.abs(normal[:, 2]),
        }
    return out


def _xlogx(x):
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(x > 0, x * np.log(np.where(x > 0, x, 1.0)), 0.0)


def add_sensor_fields(res, pts, sensor, scan):
    """Set the sensor fields of a :class:`CovarianceResult` (``sensor``, ``ray_range``,
    ``ray_cos``, ``scan_boundary``) for the points `pts` in the result's order."""
    ray = pts - sensor
    rng_ = np.linalg.norm(ray, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("ij,ij->i", ray, res.normals)) / rng_
    object.__setattr__(res, "sensor", sensor)
    object.__setattr__(res, "ray_range", rng_)
    object.__setattr__(res, "ray_cos", cos)
    object.__setattr__(res, "scan_boundary", scan)
