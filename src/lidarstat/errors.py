"""Exceptions and warnings raised by lidarstat.

Every error subclasses :class:`LidarstatError` *and* the builtin a caller would
naturally catch (``ValueError`` for bad parameters or data, ``OSError`` for files),
so ``except ValueError`` keeps working for code that does not know lidarstat.
Messages name the file (when there is one) and the problem in one line.
"""

from __future__ import annotations

__all__ = [
    "LidarstatError",
    "InvalidParameterError",
    "InvalidPointsError",
    "PointCloudReadError",
    "MalformedFileError",
    "PointCloudWriteError",
    "UnknownFormatError",
    "UnknownFieldError",
    "InsufficientNeighborsError",
    "DuplicatePointsError",
    "TooManyNeighborsError",
    "LidarstatWarning",
    "LidarstatDeprecationWarning",
]


class LidarstatError(Exception):
    """Base class of every error raised on purpose by lidarstat."""


class InvalidParameterError(LidarstatError, ValueError, TypeError):
    """A parameter has the wrong type or lies outside its valid range."""


class InvalidPointsError(LidarstatError, ValueError):
    """Point data is unusable: empty, wrong shape, NaN or infinite coordinates."""


class PointCloudReadError(LidarstatError, OSError):
    """A file could not be read as a point cloud (missing, truncated, corrupt)."""


class MalformedFileError(PointCloudReadError):
    """A file's structure contradicts itself or its size (header, VLRs, chunk table, scales),
    or reading it would allocate more than the read ceiling; found before any allocation."""


class PointCloudWriteError(LidarstatError, OSError):
    """A point cloud could not be written."""


class UnknownFormatError(LidarstatError, ValueError):
    """The file suffix does not name a supported point-cloud format."""


class UnknownFieldError(LidarstatError, KeyError):
    """A requested per-point field does not exist."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class InsufficientNeighborsError(LidarstatError, ValueError):
    """No point has enough neighbours for the requested local model."""


class DuplicatePointsError(InvalidPointsError):
    """Too many points share a location for the requested method (the message has the counts)."""


class TooManyNeighborsError(LidarstatError, ValueError):
    """A neighbourhood query would exceed the neighbour-pair ceiling (memory and time).

    Raised before anything of that size is allocated; the ceiling is
    :func:`lidarstat.neighbors.max_pairs` (environment variable
    ``LIDARSTAT_MAX_PAIRS``).
    """


class LidarstatWarning(UserWarning):
    """Recoverable problems the user should know about."""


class LidarstatDeprecationWarning(FutureWarning):
    """A parameter or option spelled in a deprecated way; it still works, and says so.

    A ``FutureWarning``, so that users see it by default (as scikit-learn and
    scikit-image do for their renamed parameters).
    """
