"""Array and parameter checks used by every public function (one message format)."""

from __future__ import annotations

import numbers

import numpy as np

from ..errors import InvalidParameterError, InvalidPointsError

#: Largest accepted coordinate magnitude: float64 spacing there is 0.125, and squared
#: distances or extents of larger values lose every digit or overflow.
MAX_COORDINATE = 1e15


def check_points(points, *, name: str = "points", min_points: int = 1, source: str | None = None):
    """Return `points` as a C-contiguous ``(N, 3)`` float64 array or raise.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Coordinates.
    name : str
        Name used in error messages.
    min_points : int
        Smallest acceptable N.
    source : str, optional
        File the points came from, prefixed to error messages.

    Raises
    ------
    InvalidPointsError
        If the array is empty, not (N, 3), not numeric, holds NaN or infinite values
        (the message counts them) or coordinates beyond ``MAX_COORDINATE`` in magnitude.
    """
    where = f"{source}: " if source else ""
    arr = np.asarray(points)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InvalidPointsError(f"{where}`{name}` must have shape (N, 3); got {arr.shape}")
    if arr.shape[0] < min_points:
        if arr.shape[0] == 0:
            raise InvalidPointsError(f"{where}`{name}` is empty (0 points)")
        raise InvalidPointsError(
            f"{where}`{name}` has {arr.shape[0]} points; at least {min_points} are needed"
        )
    try:
        if arr.dtype.kind not in "biufO":
            raise TypeError(arr.dtype)
        arr = np.ascontiguousarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidPointsError(f"{where}`{name}` holds {arr.dtype} values, not numbers"
                                 ) from None
    if arr.size == 0:
        return arr
    lo, hi = arr.min(), arr.max()  # NaN propagates through both
    if not (np.isfinite(lo) and np.isfinite(hi)):
        bad = ~np.isfinite(arr).all(axis=1)
        first = int(np.flatnonzero(bad)[0])
        raise InvalidPointsError(
            f"{where}`{name}` has {int(bad.sum())} points with NaN or infinite coordinates "
            f"(first at index {first})"
        )
    if max(-lo, hi) > MAX_COORDINATE:
        bad = (np.abs(arr) > MAX_COORDINATE).any(axis=1)
        first = int(np.flatnonzero(bad)[0])
        raise InvalidPointsError(
            f"{where}`{name}` has {int(bad.sum())} points with a coordinate beyond "
            f"{MAX_COORDINATE:.0e} in magnitude (first at index {first}, largest "
            f"{max(-lo, hi):.3g}); float64 keeps no sub-unit precision there"
        )
    return arr


def check_scalar(value, name: str, *, func: str, low=None, high=None, closed="neither",
                 integer: bool = False):
    """Validate a finite real scalar in an interval and return it as float (or int).

    ``closed`` is one of ``"neither"``, ``"left"``, ``"right"``, ``"both"``. NaN, infinite
    values, booleans, strings and other non-real values are refused whatever the interval.
    The message reads: ``The 'radius' parameter of fit_quadrics must be a float in the
    range (0, inf). Got -1.0 instead.``

    Raises
    ------
    InvalidParameterError
        If `value` is not a finite real number in the interval (an integral one when
        `integer`).
    """
    kind = "an int" if integer else "a float"
    lo = "-inf" if low is None else low
    hi = "inf" if high is None else high
    lb = "[" if closed in ("left", "both") and low is not None else "("
    rb = "]" if closed in ("right", "both") and high is not None else ")"
    got = repr(value) if len(repr(value)) <= 40 else repr(value)[:37] + "..."
    msg = (f"The '{name}' parameter of {func} must be {kind} in the range "
           f"{lb}{lo}, {hi}{rb}. Got {got} instead.")
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise InvalidParameterError(msg)
    try:
        v = float(value)
    except (OverflowError, ValueError, TypeError):  # e.g. an int beyond the float range
        raise InvalidParameterError(msg) from None
    if not np.isfinite(v) or (integer and not v.is_integer()):
        raise InvalidParameterError(msg)
    if low is not None and (v < low or (v == low and lb == "(")):
        raise InvalidParameterError(msg)
    if high is not None and (v > high or (v == high and rb == ")")):
        raise InvalidParameterError(msg)
    return int(value) if integer else v


def check_option(value, name: str, options, *, func: str):
    """Validate a string option; the message lists the valid values."""
    options = tuple(options)
    if value not in options:
        valid = ", ".join(repr(o) for o in options)
        raise InvalidParameterError(
            f"The '{name}' parameter of {func} must be one of {valid}. Got {value!r} instead."
        )
    return value
