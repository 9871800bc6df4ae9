"""Renamed parameters: the old spelling still works for a while, and says so."""

from __future__ import annotations

import functools
import warnings

from ..errors import InvalidParameterError, LidarstatDeprecationWarning

__all__ = ["renamed_parameters"]


def renamed_parameters(**renames: str):
    """Decorator accepting deprecated keyword names (``old="new"``) of a function.

    A call with an old name runs as with the new one and warns once per call with a
    :class:`~lidarstat.errors.LidarstatDeprecationWarning`; giving both is an error.

    Examples
    --------
    >>> @renamed_parameters(min_size="min_points")
    ... def f(*, min_points=3):
    ...     return min_points
    >>> import warnings
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     f(min_size=5), str(w[0].message)
    (5, 'f: min_size is deprecated; use min_points')
    """

    def wrap(func):
        @functools.wraps(func)
        def call(*args, **kwargs):
            for old, new in renames.items():
                if old in kwargs:
                    if new in kwargs:
                        raise InvalidParameterError(
                            f"{func.__name__}: give {new} only ({old} is its deprecated name)")
                    warnings.warn(f"{func.__name__}: {old} is deprecated; use {new}",
                                  LidarstatDeprecationWarning, stacklevel=2)
                    kwargs[new] = kwargs.pop(old)
            return func(*args, **kwargs)

        call.__renamed__ = dict(renames)
        return call

    return wrap
