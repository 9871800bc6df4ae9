"""``lidarstat segment IN OUT --method covariance`` (seed 003)."""

from __future__ import annotations

from . import _options as opt

#: The shared options of ``segment`` this method uses (the others are refused).
USES = frozenset({"k", "radius", "sigma", "sensor", "alpha", "min_points"})


#: ``--k`` and ``--min-points`` of this method when they are not given.
DEFAULT_K, DEFAULT_MIN_SIZE = 50, 50


def add_arguments(group):
    """Options only the covariance method has."""
    from .covariance import add_neighbourhood_arguments

    add_neighbourhood_arguments(group)
    group.add_argument("--grow-k", type=opt.int_at_least(2), default=20,
                       help="neighbours region growing looks at, nearest first [20]")
    group.add_argument("--seeds", choices=("curvature", "index"), default="curvature",
                       help="seed order: lowest surface variation first, or file order")
    group.add_argument("--min-angle", type=opt.angle_degrees(0, 90, "neither"), default=20.0,
                       help="smallest angle (degrees) between normals for an intersection")
    group.add_argument("--no-reintegration", action="store_true",
                       help="leave edge points out of the segments")
    group.add_argument("--no-adaptive-scale", action="store_true",
                       help="grow only through k-neighbourhood surface points (no planar "
                       "prefixes of 8..k neighbours: narrow faces are then missed)")
    group.add_argument("--no-refine", action="store_true",
                       help="no segment-level plane models: border points stay where the "
                       "growing put them and no strip segments (faces on 1-2 scan rows)")


def run(args, cloud):
    """Segment `cloud` by :func:`lidarstat.classify.covariance` and
    :func:`lidarstat.segment.segment_covariance`."""
    from ..classify import covariance
    from ..segment import segment_covariance

    result = covariance(
        cloud.xyz, k=DEFAULT_K if args.k is None else args.k, radius=args.radius,
        sensor=args.sensor, sigma=args.sigma, alpha=args.alpha,
        boundary_alpha=args.boundary_alpha, curvature_threshold=args.curvature_threshold,
        variance_threshold=args.variance_threshold, curved=args.curved,
        curved_alpha=args.curved_alpha, noise_estimate=args.noise_estimate,
        keep_neighbors=True)
    return segment_covariance(
        cloud.xyz, result,
        min_size=DEFAULT_MIN_SIZE if args.min_points is None else args.min_points,
        grow_k=args.grow_k, seeds=args.seeds, min_angle=args.min_angle,
        reintegration=not args.no_reintegration,
        adaptive_scale=not args.no_adaptive_scale, refine=not args.no_refine)
