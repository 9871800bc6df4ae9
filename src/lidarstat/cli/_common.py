"""Option groups every command shares, defined once, with one name per concept.

The same concept has the same option (and the same library parameter) in every command:

============================  =====================  ==================================
concept                       option                 library parameter
============================  =====================  ==================================
neighbourhood                 ``--k`` / ``--radius``  ``k`` / ``radius``
measurement noise std         ``--sigma``            ``sigma``
direction of that noise       ``--noise``            ``noise`` (``z``, ``range``, ``normal``)
scanner position              ``--sensor X Y Z``     ``sensor``
level of the main test        ``--alpha``            ``alpha``
level of another test         ``--<test>-alpha``     ``<test>_alpha``
smallest neighbourhood fitted ``--min-neighbors``    ``min_neighbors``
smallest segment or cluster   ``--min-points``       ``min_points``
random seed                   ``--seed``             ``rng``
threads / scheduler           ``--workers``,         ``workers``, ``scheduler``
                              ``--scheduler``
run summary, quiet            ``--summary-json``,    (``result.summary()``,
                              ``-q``                 ``result.params``)
============================  =====================  ==================================

Deprecated spellings still work and say so once (:func:`deprecated_alias`).
"""

from __future__ import annotations

import argparse

from .._shared._choices import Noise
from . import _options as opt

__all__ = ["SENSOR_HELP", "NOISE_CHOICES", "add_neighbourhood", "add_noise", "add_alpha",
           "add_run_outputs", "add_tiling", "add_seed", "deprecated_alias"]

#: ``--sensor`` help shared by the commands that orient toward a scanner.
SENSOR_HELP = ("scanner position; normals point to it and the range noise grows with the "
               "distance from it (default: the position the input carries, as an E57 scan "
               "pose or a FILE.sensor.json sidecar, else normals point up)")
#: Directions of the measurement noise (``--noise``).
NOISE_CHOICES = Noise.values()


def deprecated_alias(parser, old: str, new: str) -> None:
    """Record that option string `old` is a deprecated spelling of `new`.

    Add both strings to one ``add_argument`` call (``"--min-points", "--min-size"``); a
    command line using `old` runs as with `new` and warns once:
    ``--min-size is deprecated; use --min-points``.
    """
    aliases = dict(parser.get_default("_deprecated") or {})
    aliases[old] = new
    parser.set_defaults(_deprecated=aliases)


def add_neighbourhood(parser, *, k: int | None = None, radius: float | None = None,
                      k_min: int = 3, exclusive: bool = True, several_radii: bool = False,
                      k_help: str | None = None, radius_help: str | None = None):
    """``--k`` and ``--radius``: the neighbourhood of every local model.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    k, radius : optional
        Defaults (None: chosen by the method).
    k_min : int
        Smallest ``--k`` the method can fit.
    exclusive : bool
        Refuse both at once.
    several_radii : bool
        ``--radius`` takes several values (multi-scale).
    """
    g = parser.add_mutually_exclusive_group() if exclusive else parser
    g.add_argument("--k", type=opt.int_at_least(k_min), default=k,
                   help=k_help or f"neighbours per point, itself included (at least {k_min})"
                   + (f" [{k}]" if k is not None else ""))
    g.add_argument("--radius", type=opt.positive_float, default=radius,
                   nargs="+" if several_radii else None,
                   help=radius_help or "sphere radius of the neighbourhood"
                   + ("; several radii = multi-scale" if several_radii else ""))
    return g


def add_noise(parser, *, sigma_help: str | None = None, noise: bool = True,
              sensor: bool = True):
    """``--sigma``, ``--noise`` and ``--sensor``: the noise model every test uses."""
    parser.add_argument("--sigma", type=opt.positive_float, default=None,
                        help=sigma_help or "measurement noise std (default: estimated from "
                        "the data)")
    if noise:
        parser.add_argument("--noise", choices=NOISE_CHOICES, default=None,
                            help="direction of the noise sigma: 'z' (heights, airborne and "
                            "range images), 'range' (along the ray from --sensor), 'normal' "
                            "(across the surface) (default: range with a sensor, else z)")
    if sensor:
        parser.add_argument("--sensor", type=opt.finite_float, nargs=3, metavar=("X", "Y", "Z"),
                            default=None, help=SENSOR_HELP)


def add_alpha(parser, default: float = 0.05, help: str | None = None):
    """``--alpha``: the level of the method's main test."""
    parser.add_argument("--alpha", type=opt.probability, default=default,
                        help=(help or "significance level of the tests") + f" [{default:g}]")


def add_seed(parser, default: int = 0):
    """``--seed``: the random generator's seed (library ``rng``)."""
    parser.add_argument("--seed", type=opt.seed, default=default,
                        help=f"seed of the random generator [{default}]")


def add_run_outputs(parser):
    """``--summary-json`` and ``-q/--quiet``."""
    parser.add_argument("--summary-json", default=None, metavar="FILE",
                        help="write the run summary (parameters used, counts, seconds) as "
                        "JSON here")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="print nothing but errors and warnings")


def add_workers(parser, schedulers=("threads", "sync", "dask"), help_what="tiles"):
    """``--scheduler`` and ``--workers``."""
    parser.add_argument("--scheduler", choices=schedulers, default=schedulers[0],
                        help=f"how {help_what} run (default {schedulers[0]})")
    parser.add_argument("--workers", type=opt.int_at_least(1), default=None,
                        help=f"threads for the {help_what} (default: one per core)")


def add_tiling(parser, halo: str = "the neighbourhood"):
    """Out-of-core processing: ``--tile``, ``--scheduler``, ``--workers``, ``--chunk-points``.

    `halo` says how wide each tile's halo is (``--help``)."""
    g = parser.add_argument_group("large files (tiles with halos; memory independent of size)")
    g.add_argument("--tile", type=opt.positive_float, default=None, metavar="SIZE",
                   help=f"process square tiles of this side, each with a halo of {halo} "
                   "(larger than the halo); LAS/LAZ are streamed in chunks")
    add_workers(g)
    g.add_argument("--chunk-points", type=opt.int_at_least(1), default=1_000_000,
                   help="points per streamed chunk")
    return g


def given(args: argparse.Namespace) -> set[str]:
    """Destinations of the options the user typed (not left at their defaults)."""
    return set(getattr(args, "_given", ()))
