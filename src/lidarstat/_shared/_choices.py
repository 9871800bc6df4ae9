"""Fixed sets of option values of the local models: the noise model, the curvature test,
the local frame and the weights.

Each is a string enumeration: the library accepts the member or its plain string, and the
CLI derives its ``choices=`` from the members. They are defined here, below every layer,
because the command-line parser lists them while it is built and must not import the
numerics for that; the public home is :mod:`lidarstat.features`, which exports them.
"""

from __future__ import annotations

import enum

__all__ = ["Choice", "Noise", "Test", "Frame", "Weight"]


class Choice(str, enum.Enum):
    """A string option value: compares equal to its string and prints as it."""

    def __str__(self) -> str:
        return self.value

    @classmethod
    def values(cls) -> tuple[str, ...]:
        """The valid strings, in order (the CLI's ``choices=``)."""
        return tuple(m.value for m in cls)

    @classmethod
    def parse(cls, value, name: str, *, func: str) -> str:
        """`value` (a member or its string) as the plain string; an invalid one raises
        :class:`~lidarstat.errors.InvalidParameterError` listing the valid values."""
        from .validation import check_option  # NumPy: not while the parser is built

        check_option(value, name, cls.values(), func=func)
        return cls(value).value


class Noise(Choice):
    """Direction of the measurement noise ``sigma``.

    ``Z``: along z (airborne, range images); ``RANGE``: along the ray from the sensor
    (terrestrial scans); ``NORMAL``: across the surface (isotropic noise).
    """

    Z = "z"
    RANGE = "range"
    NORMAL = "normal"


class Test(Choice):
    """Family of curvature tests: ``CALIBRATED`` (sandwich covariance, Satterthwaite
    chi-square, exact planarity test) or ``PAPER`` (Crosilla et al. 2009 as printed)."""

    __test__ = False  # not a pytest test class

    CALIBRATED = "calibrated"
    PAPER = "paper"


class Frame(Choice):
    """Local frame of a quadric: height along ``Z``, along the PCA normal (``PCA``) or
    ``AUTO`` (z where the surface is nearly horizontal, else the PCA normal)."""

    Z = "z"
    AUTO = "auto"
    PCA = "pca"


class Weight(Choice):
    """Weights of a jet fit: ``TRICUBE`` of the distance, or ``NONE`` (CGAL's fit)."""

    TRICUBE = "tricube"
    NONE = "none"
