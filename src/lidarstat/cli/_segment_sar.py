"""``lidarstat segment IN OUT --method sar``: SAR models and the Forward Search (seed 002).

Shared options used: ``--radius`` (plane-regression bandwidth b; default chosen by
``--criterion``), ``--sigma``, ``--alpha`` (planarity test), ``--min-points``.
"""

from __future__ import annotations

from . import _options as opt

#: The shared options of ``segment`` this method uses (the others are refused).
USES = frozenset({"radius", "sigma", "alpha", "min_points"})

#: ``--min-points`` of this method when it is not given.
DEFAULT_MIN_POINTS = 30


def add_arguments(group):
    """Options only the SAR method has."""
    from ..features import AdaptiveBandwidth, BandwidthCriterion
    from ..segment import StopRule
    from ._common import deprecated_alias

    deprecated_alias(group, "--fs-envelope", "--envelope-alpha")
    group.add_argument("--criterion", default=BandwidthCriterion.RICE.value,
                       choices=[m.value for m in BandwidthCriterion],
                       help="bandwidth selector when --radius is omitted (default rice)")
    group.add_argument("--adaptive", nargs="?", const=AdaptiveBandwidth.GEARY.value,
                       default=AdaptiveBandwidth.MULTISCALE.value,
                       choices=[m.value for m in AdaptiveBandwidth],
                       help="per-point bandwidths: 'multiscale' (default: the largest of b, "
                       "0.75 b, 0.5 b whose local plane passes the planarity test), 'geary' "
                       "(Geary's local indicator; also the bare flag) or 'none'")
    group.add_argument("--sar-degree", default="1",
                       type=opt.one_of_or(("auto",), opt.int_range(1, 3), "1, 2, 3 or 'auto'"),
                       help="polynomial order of the units: 1 (planes), 2, 3 or 'auto' "
                       "(t tests up to 3)")
    group.add_argument("--edge-alpha", type=opt.probability, default=0.05,
                       help="level of the height/slope tests of region growing (0.05)")
    group.add_argument("--search", type=opt.positive_float, default=None,
                       help="search-area distance from a raw cluster (default 3 b)")
    group.add_argument("--w-radius", type=opt.positive_float, default=None,
                       help="radius of the SAR adjacency W (default 1.5 x point spacing)")
    group.add_argument("--fs-alpha", type=opt.probability, default=0.001,
                       help="level of the Forward Search F test")
    group.add_argument("--envelope-alpha", "--fs-envelope", dest="envelope_alpha",
                       type=opt.probability, default=0.001,
                       help="level of the Forward Search deletion-residual envelope")
    group.add_argument("--fs-stop", default=StopRule.BOTH.value,
                       choices=[m.value for m in StopRule],
                       help="Forward Search stopping rule")
    group.add_argument("--fs-block", type=opt.int_at_least(1), default=1,
                       help="points added per Forward Search step (1 = unitary)")
    group.add_argument("--outlier-alpha", type=opt.probability_or_zero, default=0.01,
                       help="per-point level of the final outlier test of the points the "
                       "search added (iterated data snooping, deletion residuals with a "
                       "robust segment scale fixed before the iterations; 0.01); 0 "
                       "disables it")
    group.add_argument("--gof-alpha", type=opt.probability_or_zero, default=0.001,
                       help="level of the per-segment goodness-of-fit test (residual scale "
                       "against the noise, chi-square with the SAR correlation); a "
                       "segment it rejects is split into two surfaces when that removes "
                       "at least half of its residual sum of squares (0.001); 0 disables "
                       "it")
    group.add_argument("--no-planes", dest="planes", action="store_false",
                       help="keep the SAR units alone: no second stage of planes in their "
                       "own frame (steep faces, walls, faces narrower than the bandwidth) "
                       "among the points no unit took")
    group.add_argument("--diagnostics", default=None, metavar="DIR",
                       help="write Forward Search monitoring plots (PNG) to DIR")


def run(args, cloud):
    """Segment `cloud` by :func:`lidarstat.segment.segment_sar`."""
    from ..segment import segment_sar

    deg = None if args.sar_degree == "auto" else int(args.sar_degree)
    min_points = DEFAULT_MIN_POINTS if args.min_points is None else args.min_points
    return segment_sar(cloud.xyz, radius=args.radius, criterion=args.criterion,
                       sigma=args.sigma, alpha=args.alpha, edge_alpha=args.edge_alpha,
                       fs_alpha=args.fs_alpha, envelope_alpha=args.envelope_alpha,
                       fs_stop=args.fs_stop, degree=deg, adaptive=args.adaptive,
                       search=args.search, w_radius=args.w_radius,
                       min_points=min_points,
                       fs_block=args.fs_block, outlier_alpha=_level_or_off(args.outlier_alpha),
                       gof_alpha=_level_or_off(args.gof_alpha), planes=args.planes)


def _level_or_off(alpha):
    """A test level where 0 switches the test off (None for the library)."""
    return None if alpha == 0 else alpha
