"""The domain of every command-line option, checked when the command line is parsed.

Each option's ``type=`` is one of the converters below, so a value outside its domain is
refused before any file is read, with the option named as the user typed it::

    lidarstat covariance: error: argument --k: invalid value '0': must be an integer >= 3

Converters are built from a few declarative factories (:func:`real`, :func:`integer`,
:func:`one_of_or`); conditions between options (``--tile`` larger than ``--radius``) are
registered on the parser with :func:`add_check`. :class:`Parser` prints every usage error
as one line, and :func:`error_line` gives a library error raised while processing a file
that file's name and the option names of the command line.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

from ..errors import LidarstatError

__all__ = [
    "Parser", "add_check", "error_line", "real", "integer", "one_of_or", "codes_list",
    "finite_float", "positive_float", "nonnegative_float", "probability",
    "probability_or_zero", "int_at_least", "int_range", "angle_degrees", "seed",
]


def _fail(text, requirement):
    raise argparse.ArgumentTypeError(f"invalid value {text!r}: {requirement}")


def _interval(low, high, closed):
    """Human wording of an interval: ``> 0``, ``>= 0``, ``in (0, 1)``, ``in [0, 180]``."""
    left = closed in ("left", "both")
    right = closed in ("right", "both")
    if high is None:
        return "" if low is None else f"{'>=' if left else '>'} {low:g}"
    if low is None:
        return f"{'<=' if right else '<'} {high:g}"
    return f"in {'[' if left else '('}{low:g}, {high:g}{']' if right else ')'}"


def real(low=None, high=None, closed="neither", *, what="number"):
    """A converter to a finite float in an interval.

    Parameters
    ----------
    low, high : float, optional
        Bounds of the interval; None for no bound.
    closed : {"neither", "left", "right", "both"}
        Which bounds belong to the interval.
    what : str
        Noun of the message (``"number"``, ``"probability"``, ``"angle in degrees"``).

    Returns
    -------
    callable
        ``convert(text) -> float``, raising :class:`argparse.ArgumentTypeError` with a
        message such as ``invalid value 'nan': must be a finite number > 0``.
    """
    bound = _interval(low, high, closed)
    bound = f" {bound}" if bound else ""
    article = "an" if what[0] in "aeiou" else "a"
    requirement = f"must be {article} {what}{bound}"

    def convert(text):
        try:
            v = float(text)
        except (TypeError, ValueError):
            _fail(text, requirement)
        if not math.isfinite(v):
            _fail(text, f"must be a finite {what}{bound}")
        if low is not None and (v < low or (v == low and closed not in ("left", "both"))):
            _fail(text, requirement)
        if high is not None and (v > high or (v == high and closed not in ("right", "both"))):
            _fail(text, requirement)
        return v

    convert.__name__ = "number"
    return convert


def integer(low=None, high=None):
    """A converter to an int in ``[low, high]`` (either bound may be None).

    Returns
    -------
    callable
        ``convert(text) -> int``; the message reads ``must be an integer >= 1`` or
        ``must be an integer from 1 to 6``.
    """
    if low is not None and high is not None:
        requirement = f"must be an integer from {low} to {high}"
    else:
        requirement = "must be an integer" + (f" >= {low}" if low is not None else "") + \
            (f" <= {high}" if high is not None else "")

    def convert(text):
        try:
            v = int(str(text).strip())
        except ValueError:
            _fail(text, requirement)
        if (low is not None and v < low) or (high is not None and v > high):
            _fail(text, requirement)
        return v

    convert.__name__ = "integer"
    return convert


def one_of_or(words, other, description):
    """A converter accepting one of `words` as is, else ``other(text)``.

    Parameters
    ----------
    words : tuple of str
        Literal values kept as strings (``"auto"``, ``"silverman"``).
    other : callable
        Converter of every other value (:func:`real` or :func:`integer`).
    description : str
        What a valid value is, for the message (``"1, 2, 3 or 'auto'"``).
    """
    def convert(text):
        if text in words:
            return text
        try:
            return other(text)
        except argparse.ArgumentTypeError:
            _fail(text, f"must be {description}")

    convert.__name__ = "value"
    return convert


def codes_list(text):
    """Comma-separated ASPRS class codes (integers 0-255), at least one, as a tuple."""
    requirement = "must be comma-separated class codes from 0 to 255, e.g. 2,8,9"
    parts = [p.strip() for p in str(text).split(",")]
    if not any(parts):
        _fail(text, requirement)
    codes = []
    for p in parts:
        if not p:
            continue
        try:
            v = int(p)
        except ValueError:
            _fail(text, requirement)
        if not 0 <= v <= 255:
            _fail(text, requirement)
        codes.append(v)
    return tuple(codes)


finite_float = real()
positive_float = real(0)
nonnegative_float = real(0, closed="left")
probability = real(0, 1, what="probability")
#: A test level where 0 switches the test off.
probability_or_zero = real(0, 1, "left", what="probability")
seed = integer(0)


def int_at_least(low):
    """A converter to an int >= `low`."""
    return integer(low)


def int_range(low, high):
    """A converter to an int from `low` to `high`, both included."""
    return integer(low, high)


def angle_degrees(low, high, closed="right"):
    """A converter to an angle in degrees in the interval from `low` to `high`."""
    return real(low, high, closed, what="angle in degrees")


# --------------------------------------------------------------------------- parser
def add_check(parser, check):
    """Register ``check(namespace) -> (option, message) | None``, run after parsing.

    A failed check is reported like a bad value: ``argument --tile: <message>``.
    """
    parser.set_defaults(_checks=[*(parser.get_default("_checks") or ()), check])


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, with cross-option checks.

    Subcommand parsers made by ``add_subparsers().add_parser`` are of this class too.
    """

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")

    def _typed_options(self, args) -> dict[str, str]:
        """Option strings typed on the command line (full spelling) -> their destination.

        Abbreviations are resolved as argparse resolves them (a unique prefix); the
        tokens after ``--`` are values, not options.
        """
        import sys

        tokens = sys.argv[1:] if args is None else list(args)
        found: dict[str, str] = {}
        known = self._option_string_actions
        for tok in tokens:
            if tok == "--":
                break
            if not isinstance(tok, str) or not tok.startswith("-") or len(tok) < 2:
                continue
            if self._negative_number_matcher.match(tok):
                continue
            name = tok.split("=", 1)[0]
            if name not in known and name.startswith("--") and self.allow_abbrev:
                hits = [o for o in known if o.startswith(name)]
                name = hits[0] if len({known[h].dest for h in hits}) == 1 and hits else name
            action = known.get(name)
            if action is not None and action.dest != "help":
                found[name] = action.dest
        return found

    def parse_known_args(self, args=None, namespace=None):
        typed = self._typed_options(args)
        namespace, extras = super().parse_known_args(args, namespace)
        namespace._given = {*getattr(namespace, "_given", ()), *typed.values()}
        aliases = self.get_default("_deprecated") or {}
        namespace._deprecations = [*getattr(namespace, "_deprecations", ()),
                                   *(f"{t} is deprecated; use {aliases[t]}"
                                     for t in typed if t in aliases)]
        if not hasattr(namespace, "_option_names"):
            namespace._option_names = {
                a.dest: next((o for o in a.option_strings if o.startswith("--")),
                             a.option_strings[-1])
                for a in self._actions if a.option_strings and a.dest != "help"}
            # messages name an option as the user typed it
            namespace._option_names.update({dest: text for text, dest in typed.items()})
        checks = self.get_default("_checks")
        if checks:
            for check in checks:
                failed = check(namespace)
                if failed:
                    self.error(f"argument {failed[0]}: {failed[1]}")
        return namespace, extras


# --------------------------------------------------------------------------- messages
#: Attributes of a parsed command line holding the input a command processes.
_INPUTS = ("input", "file", "result")
#: Attributes holding any other path of the command line.
_PATHS = ("output", "reference", "table", "lines", "summary_json", "report", "json",
          "diagnostics", "outdir")
_PARAMETER = re.compile(r"The '(\w+)' parameter of \w+ must be")
_QUOTED = re.compile(r"`(\w+)`")


def _starts_with_path(msg, args):
    head = msg.split(": ", 1)[0] if ": " in msg else ""
    typed = []
    for a in _INPUTS + _PATHS:  # a catalogue's IN may be several paths
        v = getattr(args, a, None)
        typed += list(v) if isinstance(v, (list, tuple)) else [v]
    for p in typed:
        if p and (msg.startswith(str(p)) or msg.startswith(str(Path(p)))):
            return True
    if not head or " " in head:
        return False
    return Path(head).exists() or "/" in head or Path(head).suffix != ""


def error_line(exc, args) -> str:
    """One line reporting `exc`, raised by a command run with the parsed `args`.

    The message keeps its first line; a library parameter the command line sets is named
    by its option (``--k`` for ``'k'`` or a back-quoted k); a message that does not start
    with a path is prefixed by the command's input file as typed.

    Parameters
    ----------
    exc : BaseException
        The error.
    args : argparse.Namespace or None
        The parsed command line.

    Returns
    -------
    str
        The text after ``lidarstat: error:``.
    """
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    if args is None:
        return msg
    options = getattr(args, "_option_names", {})

    def option(m):
        name = options.get(m.group(1))
        return f"{name} must be" if name else m.group(0)

    msg = _PARAMETER.sub(option, msg, count=1)
    msg = _QUOTED.sub(lambda m: options.get(m.group(1), m.group(0)), msg)
    src = next((getattr(args, a) for a in _INPUTS if getattr(args, a, None)), None)
    if isinstance(src, (list, tuple)):
        src = " ".join(map(str, src))
    if src is not None and isinstance(exc, LidarstatError) and not _starts_with_path(msg, args):
        msg = f"{src}: {msg}"
    return msg
