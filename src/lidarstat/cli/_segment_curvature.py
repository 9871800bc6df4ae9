"""``lidarstat segment IN OUT --method curvature``: units from tested HK classes (seed 000).

Shared options used: ``--radius`` (curvature bandwidth; default the automatic scale), ``--sigma``,
``--noise``, ``--sensor``, ``--alpha``, ``--min-points``.
"""

from __future__ import annotations

from .._shared._choices import Frame
from . import _options as opt

#: The shared options of ``segment`` this method uses (the others are refused).
USES = frozenset({"radius", "sigma", "noise", "sensor", "alpha", "min_points"})

#: ``--min-points`` of this method when it is not given.
DEFAULT_MIN_POINTS = 30


def add_arguments(group):
    """Options only the curvature method has."""
    from ._common import deprecated_alias

    deprecated_alias(group, "--curvature-frame", "--frame")
    deprecated_alias(group, "--normal-angle", "--max-angle")
    group.add_argument("--max-angle", "--normal-angle", type=opt.angle_degrees(0, 180),
                       default=10.0, dest="max_angle",
                       help="largest angle between the normals of neighbours in one unit "
                       "(degrees) [10]")
    group.add_argument("--frame", "--curvature-frame", default=Frame.PCA.value,
                       choices=Frame.values(), dest="frame",
                       help="local frame of the curvature quadrics (default pca, any "
                       "orientation; z is the paper's); --refine models walls in their own "
                       "plane")
    group.add_argument("--merge-alpha", type=opt.probability, default=0.001,
                       dest="merge_alpha",
                       help="level of the model tests that refuse to merge two units whose "
                       "union is no plane (planar units) or no quadric (curved units) "
                       "[0.001]")
    group.add_argument("--refine", action="store_true",
                       help="refine the units by SAR-FS (order 1 planar, 2 curved) and "
                       "intersect adjacent surfaces")


def run(args, cloud, **library):
    """Segment `cloud` by :func:`lidarstat.segment.segment_curvature` (`library`: more of
    its arguments, e.g. a precomputed ``curv``)."""
    from ..segment import segment_curvature

    return segment_curvature(cloud.xyz, radius=args.radius, sigma=args.sigma,
                             alpha=args.alpha, max_angle=args.max_angle,
                             min_points=DEFAULT_MIN_POINTS if args.min_points is None
                             else args.min_points, refine=args.refine,
                             frame=args.frame, noise=args.noise,
                             sensor=args.sensor, merge_alpha=args.merge_alpha, **library)
