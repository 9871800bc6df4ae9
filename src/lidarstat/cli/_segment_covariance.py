"""``lidarstat segment IN OUT --method covariance`` (seed 003)."""

from __future__ import annotations

from . import _options as opt

#: The shared options of ``segment`` this method uses (the others are refused).
USES = frozenset({"k", "radius", "sigma", "noise", "sensor", "alpha", "min_points"})


#: ``--min-points`` of this method when it is not given (without ``--k`` and
#: ``--radius`` the neighbourhood sizes are chosen per point).
DEFAULT_MIN_POINTS = 50


def add_arguments(group):
    """Options only the covariance method has: the classification's tests (the regions
    grow on its classes) and the region growing's."""
    from ..segment import SeedOrder
    from .covariance import add_classification_arguments

    add_classification_arguments(group)
    group.add_argument("--grow-k", type=opt.int_at_least(2), default=20,
                       help="neighbours region growing looks at, nearest first [20]")
    group.add_argument("--seeds", choices=[o.value for o in SeedOrder], default="curvature",
                       help="seed order: lowest surface variation first, or file order")
    group.add_argument("--min-angle", type=opt.angle_degrees(0, 90, "neither"), default=20.0,
                       help="smallest angle (degrees) between normals for an intersection")
    group.add_argument("--no-reintegration", action="store_true",
                       help="leave edge points out of the segments")


def run(args, cloud):
    """Segment `cloud` by :func:`lidarstat.classify.covariance` and
    :func:`lidarstat.segment.segment_covariance`."""
    from ..classify import covariance
    from ..segment import segment_covariance
    from .covariance import classification_options

    result = covariance(
        cloud.xyz, k=args.k, radius=args.radius, sensor=args.sensor, sigma=args.sigma,
        noise=args.noise, alpha=args.alpha, keep_neighbors=True,
        **classification_options(args, args.sensor))
    return segment_covariance(
        cloud.xyz, result,
        min_points=DEFAULT_MIN_POINTS if args.min_points is None else args.min_points,
        grow_k=args.grow_k, seeds=args.seeds, min_angle=args.min_angle,
        reintegration=not args.no_reintegration)
