"""``lidarstat segment IN OUT --method curvature``: units from tested HK classes (seed 000).

Shared options used: ``--radius`` (curvature bandwidth, required), ``--sigma``,
``--alpha``, ``--min-size``.
"""

from __future__ import annotations

from . import _options as opt

#: ``--min-size`` of this method when it is not given.
DEFAULT_MIN_SIZE = 30


def add_arguments(group):
    """Options only the curvature method has."""
    group.add_argument("--normal-angle", type=opt.angle_degrees(0, 180), default=10.0,
                       help="largest normal angle between neighbours of a unit (degrees)")
    group.add_argument("--curvature-frame", default="z", choices=("z", "auto", "pca"),
                       help="local frame of the curvature quadrics (default z; 'auto' or "
                       "'pca' with --curvature-noise normal also find walls, which --refine "
                       "models in their own plane)")
    group.add_argument("--curvature-noise", default=None, choices=("z", "range", "normal"),
                       help="direction of the noise sigma (default z, or range with --sensor; "
                       "'normal' for isotropic noise, needed for walls)")
    group.add_argument("--refine", action="store_true",
                       help="refine the units by SAR-FS (order 1 planar, 2 curved) and "
                       "intersect adjacent surfaces")


def run(args, cloud):
    """Segment `cloud` by :func:`lidarstat.segment.segment_curvature`."""
    from ..errors import InvalidParameterError
    from ..segment import segment_curvature

    if args.radius is None:
        raise InvalidParameterError("--method curvature needs --radius (the curvature "
                                    "bandwidth)")
    return segment_curvature(cloud.xyz, radius=args.radius, sigma=args.sigma,
                             alpha=args.alpha, max_angle=args.normal_angle,
                             min_size=DEFAULT_MIN_SIZE if args.min_size is None
                             else args.min_size, refine=args.refine,
                             frame=args.curvature_frame, noise=args.curvature_noise,
                             sensor=args.sensor)
