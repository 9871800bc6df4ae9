"""The result type of every generator and the exact surface-type rule.

Sign convention (a library-wide contract): the unit normal points "up" (+z) for height
fields and toward the viewer for range scans, and a surface bending *away* from its normal
(convex, seen from the normal side) has H < 0.  kmin <= kmax, K = kmin*kmax,
H = (kmin + kmax)/2.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidParameterError

__all__ = [
    "SyntheticCloud",
    "point_class_truth",
    "neighborhood_class_truth",
    "SURFACE_TYPE_NAMES",
    "surface_type_from_curvature",
    "principal_curvatures",
]

#: Surface type codes shared with :mod:`lidarstat.classify`.
SURFACE_TYPE_NAMES = {
    0: "unclassified",
    1: "planar",
    2: "parabolic ridge",
    3: "parabolic valley",
    4: "elliptic peak",
    5: "elliptic pit",
    6: "saddle ridge",
    7: "saddle valley",
    8: "minimal saddle",
}


def surface_type_from_curvature(K, H):
    """Surface type code (0..8) from *exact* Gaussian and mean curvature.

    Zero means exactly ``0.0``: the generators set curvatures that vanish analytically to
    exact zeros, so no tolerance is applied here.

    Parameters
    ----------
    K, H : array_like
        Gaussian and mean curvature (same shape).

    Returns
    -------
    numpy.ndarray of uint8
        1 planar (K=0, H=0), 2 parabolic ridge (K=0, H<0), 3 parabolic valley (K=0, H>0),
        4 elliptic peak (K>0, H<0), 5 elliptic pit (K>0, H>0), 6 saddle ridge (K<0, H<0),
        7 saddle valley (K<0, H>0), 8 minimal saddle (K<0, H=0); 0 for the impossible
        combination K>0, H=0 and for NaN.

    Examples
    --------
    >>> surface_type_from_curvature([0.0, 0.0, 1.0, -1.0], [0.0, -0.5, -1.0, 0.0]).tolist()
    [1, 2, 4, 8]
    """
    K = np.asarray(K, dtype=np.float64)
    H = np.asarray(H, dtype=np.float64)
    out = np.zeros(np.broadcast(K, H).shape, dtype=np.uint8)
    kz, kp, kn = K == 0, K > 0, K < 0
    hz, hp, hn = H == 0, H > 0, H < 0
    out[kz & hz] = 1
    out[kz & hn] = 2
    out[kz & hp] = 3
    out[kp & hn] = 4
    out[kp & hp] = 5
    out[kn & hn] = 6
    out[kn & hp] = 7
    out[kn & hz] = 8
    return out


def principal_curvatures(K, H):
    """Return ``(kmin, kmax) = H -/+ sqrt(max(H^2 - K, 0))``.

    Examples
    --------
    >>> kmin, kmax = principal_curvatures(0.0, -0.5)
    >>> float(kmin), float(kmax)
    (-1.0, 0.0)
    """
    K = np.asarray(K, dtype=np.float64)
    H = np.asarray(H, dtype=np.float64)
    root = np.sqrt(np.maximum(H * H - K, 0.0))
    return H - root, H + root


def _readonly(a):
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class SyntheticCloud:
    """A synthetic point cloud with exact per-point ground truth.

    All truth arrays refer to the noise-free sample (``meta["xyz_true"]``); ``xyz`` is that
    sample plus Gaussian noise of std `sigma` along z.  Arrays are read-only.

    Attributes
    ----------
    xyz : ndarray, shape (N, 3), float64
        Coordinates (with noise).
    normal : ndarray, shape (N, 3), float64
        True unit normals, oriented up (+z) / toward the viewer; ``normal[:, 2] > 0``.
    K, H, kmin, kmax : ndarray, shape (N,), float64
        True Gaussian, mean and principal curvatures (H < 0 on convex surfaces).
    surface_type : ndarray, shape (N,), uint8
        True surface type code (see :data:`SURFACE_TYPE_NAMES`), from the exact K, H.
    face : ndarray, shape (N,), int32
        Face / primitive-surface id (``meta["faces"][id]`` describes it); -1 for none.
    edge_distance : ndarray, shape (N,), float64
        Distance to the nearest face boundary, crease or silhouette / occlusion jump
        (how it is measured is stated in ``meta["edge_distance"]``); select interior
        points with ``edge_distance > radius``.
    sigma : float
        Standard deviation of the noise added along z.
    scanner : ndarray, shape (3,), or None
        Scanner position; None for orthographic (grid) views along -z.
    name : str
        Scene name.
    meta : dict
        Parameters of the scene and extras (``xyz_true``, ``faces``, ...).
    fields : dict of str to ndarray
        Further per-point truth of a scene (first axis N), e.g. ``boundary_distance``,
        ``range``, ``row``, ``col`` of terrestrial scans or ``roof_plane``,
        ``building_id``, ``height_above_ground`` of airborne scenes; written beside the
        coordinates by :meth:`to_fields`.  Empty for the analytic patches.
    attributes : dict of str to ndarray
        Simulated *sensor* attributes under laspy's standard names (``intensity``,
        ``return_number``, ``number_of_returns``, ``classification``, ``scan_angle``,
        ``gps_time``, ...); as the attributes of a :class:`lidarstat.io.PointCloud`
        (``PointCloud(xyz=scene.xyz, attributes=scene.attributes)``) they are written to
        the standard LAS dimensions.
    """

    xyz: np.ndarray
    normal: np.ndarray
    K: np.ndarray
    H: np.ndarray
    kmin: np.ndarray
    kmax: np.ndarray
    surface_type: np.ndarray
    face: np.ndarray
    edge_distance: np.ndarray
    sigma: float
    scanner: np.ndarray | None
    name: str
    meta: dict = field(default_factory=dict)
    fields: dict = field(default_factory=dict)
    attributes: dict = field(default_factory=dict)

    def __post_init__(self):
        xyz = np.asarray(self.xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InvalidParameterError(f"SyntheticCloud.xyz must be (N, 3); got {xyz.shape}")
        n = xyz.shape[0]
        conv = {
            "xyz": (xyz, np.float64, (n, 3)),
            "normal": (self.normal, np.float64, (n, 3)),
            "K": (self.K, np.float64, (n,)),
            "H": (self.H, np.float64, (n,)),
            "kmin": (self.kmin, np.float64, (n,)),
            "kmax": (self.kmax, np.float64, (n,)),
            "surface_type": (self.surface_type, np.uint8, (n,)),
            "face": (self.face, np.int32, (n,)),
            "edge_distance": (self.edge_distance, np.float64, (n,)),
        }
        for key, (val, dtype, shape) in conv.items():
            arr = np.asarray(val, dtype=dtype)
            if arr.shape != shape:
                raise InvalidParameterError(
                    f"SyntheticCloud.{key} must have shape {shape}; got {arr.shape}"
                )
            object.__setattr__(self, key, _readonly(arr))
        for attr in ("fields", "attributes"):
            checked = {}
            for key, val in dict(getattr(self, attr)).items():
                arr = np.asarray(val)
                if arr.ndim < 1 or arr.shape[0] != n:
                    raise InvalidParameterError(
                        f"SyntheticCloud.{attr}[{key!r}] must have {n} rows; got {arr.shape}")
                checked[key] = _readonly(arr)
            object.__setattr__(self, attr, checked)
        if self.scanner is not None:
            object.__setattr__(self, "scanner", _readonly(np.asarray(self.scanner, float)))
        object.__setattr__(self, "sigma", float(self.sigma))

    def __len__(self) -> int:
        return self.xyz.shape[0]

    def __repr__(self) -> str:
        return (f"SyntheticCloud(name={self.name!r}, n={len(self)}, sigma={self.sigma}, "
                f"faces={len(self.meta.get('faces', []))})")

    def to_fields(self) -> dict:
        """Per-point truth to write beside the coordinates.

        Returns
        -------
        dict
            ``{"true_K": float64, "true_H": float64, "true_surface_type": uint8,
            "face": int32}``, each of shape (N,), followed by copies of the scene's extra
            :attr:`fields` (none for the analytic patches).

        Examples
        --------
        >>> from lidarstat.synth import make_plane
        >>> sorted(make_plane(extent=0.2, spacing=0.1).to_fields())
        ['face', 'true_H', 'true_K', 'true_surface_type']
        """
        return {
            "true_K": self.K.copy(),
            "true_H": self.H.copy(),
            "true_surface_type": self.surface_type.copy(),
            "face": self.face.copy(),
            **{k: np.array(v) for k, v in self.fields.items()},
        }


def _build(*, xyz_true, normal, K, H, face, edge_distance, sigma, rng, name, meta,
           kmin=None, kmax=None, scanner=None):
    """Add z noise, derive kmin/kmax and types, and assemble a SyntheticCloud."""
    xyz_true = np.ascontiguousarray(xyz_true, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64) + 0.0  # turn -0.0 into +0.0
    H = np.asarray(H, dtype=np.float64) + 0.0
    if kmin is None or kmax is None:
        kmin, kmax = principal_curvatures(K, H)
    xyz = xyz_true.copy()
    if sigma > 0:
        xyz[:, 2] += sigma * rng.standard_normal(xyz.shape[0])
    meta = dict(meta)
    meta["xyz_true"] = _readonly(xyz_true)
    return SyntheticCloud(
        xyz=xyz, normal=normal, K=K, H=H, kmin=np.asarray(kmin, float) + 0.0,
        kmax=np.asarray(kmax, float) + 0.0, surface_type=surface_type_from_curvature(K, H),
        face=face, edge_distance=edge_distance, sigma=sigma, scanner=scanner, name=name,
        meta=meta,
    )


def point_class_truth(cloud: SyntheticCloud, radius: float) -> np.ndarray:
    """True surface / edge / boundary class of every point for a neighbourhood `radius`.

    The codes are those of ``lidarstat covariance``'s ``point_class``: 3 *boundary* where
    ``fields["boundary_distance"] < radius`` (the neighbourhood sphere reaches past the
    end of the visible surface), else 2 *edge* where ``edge_distance < radius`` (it
    reaches a crease), else 1 *surface*.  Boundary wins over edge because a sphere cut by
    a border is one-sided whatever creases it also holds.  Scenes without
    ``boundary_distance`` get no boundary class; NaN distances count as far.

    Parameters
    ----------
    cloud : SyntheticCloud
    radius : float
        Neighbourhood radius (same units as the cloud), > 0.

    Returns
    -------
    numpy.ndarray of uint8, shape (N,)

    Examples
    --------
    >>> from lidarstat.synth import make_plane
    >>> c = make_plane(extent=1.0, spacing=0.1)
    >>> np.bincount(point_class_truth(c, 0.15)).tolist()
    [0, 49, 72]
    """
    if not (np.isfinite(radius) and radius > 0):
        raise InvalidParameterError(
            f"The 'radius' parameter of point_class_truth must be a float in the range "
            f"(0, inf). Got {radius!r} instead.")
    out = np.ones(len(cloud), dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        out[cloud.edge_distance < radius] = 2
        bd = cloud.fields.get("boundary_distance")
        if bd is not None:
            out[bd < radius] = 3
    return out


def neighborhood_class_truth(cloud: SyntheticCloud, neighborhoods, *,
                             boundary_band: float = 0.5) -> np.ndarray:
    """True class of every point judged on the neighbourhood a method actually used.

    *Edge* (2) where the neighbourhood holds a point of another face (it straddles a
    crease, whichever face is seen), *boundary* (3) where ``boundary_distance`` is below
    `boundary_band` times the point's own neighbourhood radius (its farthest neighbour),
    boundary winning as in :func:`point_class_truth`; else *surface* (1). Unlike
    :func:`point_class_truth` with one radius, the zones follow the density of the scan
    (a terrestrial scan's neighbourhoods grow with the range), and a crease whose other
    face is not seen (a hidden window jamb) makes no edge: no neighbour lies across it.

    Parameters
    ----------
    cloud : SyntheticCloud
    neighborhoods : Neighborhoods
        One row per point of `cloud` (e.g. ``covariance_features(...,
        keep_neighbors=True).neighborhoods``).
    boundary_band : float
        Boundary zone as a share of the neighbourhood radius.

    Returns
    -------
    numpy.ndarray of uint8, shape (N,)

    Examples
    --------
    >>> from lidarstat.synth import make_plane
    >>> from lidarstat.neighbors import knn_neighbors
    >>> c = make_plane(extent=1.0, spacing=0.1)
    >>> np.bincount(neighborhood_class_truth(c, knn_neighbors(c.xyz, 5))).tolist()
    [0, 121]
    """
    n = len(cloud)
    if len(neighborhoods) != n:
        raise InvalidParameterError(
            f"neighborhood_class_truth: {len(neighborhoods)} neighbourhoods for {n} points")
    if not (np.isfinite(boundary_band) and boundary_band > 0):
        raise InvalidParameterError(
            f"The 'boundary_band' parameter of neighborhood_class_truth must be a float in "
            f"the range (0, inf). Got {boundary_band!r} instead.")
    counts = np.diff(neighborhoods.indptr)
    rows = np.repeat(np.arange(n), counts)
    other = np.bincount(rows, weights=cloud.face[neighborhoods.indices] != cloud.face[rows],
                        minlength=n)
    reach = np.zeros(n)
    np.maximum.at(reach, rows, neighborhoods.distances)
    out = np.ones(n, dtype=np.uint8)
    out[other > 0] = 2
    bd = cloud.fields.get("boundary_distance")
    if bd is not None:
        with np.errstate(invalid="ignore"):
            out[bd < boundary_band * reach] = 3
    return out
