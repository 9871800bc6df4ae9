"""``lidarstat segment --method ridges``: surface units cut along the ridge lines."""

from __future__ import annotations

from . import _options as opt

#: The shared options of ``segment`` this method uses (the others are refused).
USES = frozenset({"k", "radius", "sigma", "noise", "sensor", "alpha", "min_points"})

#: ``--min-points`` of this method when it is not given.
DEFAULT_MIN_POINTS = 50


def add_arguments(group):
    """Options of the ridges method (the shared ones live in cli/segment.py)."""
    from .ridges import add_jet_arguments

    # the jets' neighbourhood is the shared --radius (or --k)
    group.add_argument("--ridge-grow-k", type=opt.int_at_least(2), default=8,
                       help="neighbours of the region-growing graph")
    group.add_argument("--band", type=opt.positive_float, default=None,
                       help="half-width of the barrier band around ridge lines")
    group.add_argument("--extend", type=opt.nonnegative_float, default=None,
                       help="longest extension of ridge lines at their ends (default the "
                            "jet radius; 0 none)")
    add_jet_arguments(group)


def run(args, cloud):
    """Ridges, then the units between the ridge band and the jets the chi-square rejects."""
    from ..features import radius_ladder
    from ..segment import ridge_segments, ridges

    # neither --radius nor --k: one radius from the data, the smallest of the automatic
    # scale's ladder (about 48 points, three times a degree-4 jet's minimum). Creases, the
    # barriers, are C0 discontinuities that jets reject at any scale; per-point radii
    # (wider beside the creases) widen the rejection bands and lose faces
    # (docs/methods/jets.md, validation)
    # The crease label is left out: its points as barriers cost hip_roof two of its six
    # roof planes (benchmarks/results_ridges.json, key scenes_with_creases)
    radius = args.radius
    if radius is None and args.k is None:
        radius = float(radius_ladder(cloud.xyz)[0])
    res = ridges(cloud.xyz, radius=radius, k=None if radius is not None else args.k,
                 sigma=args.sigma, alpha=args.alpha, weight=args.weight, sensor=args.sensor,
                 noise=args.noise, ratio=args.ratio, min_length=args.min_length,
                 creases=False)
    min_points = DEFAULT_MIN_POINTS if args.min_points is None else args.min_points
    return ridge_segments(cloud.xyz, res, grow_k=args.ridge_grow_k, width=args.band,
                          min_points=min_points, extend=args.extend)
