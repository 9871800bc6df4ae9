"""The measurement-noise model of the local fits: which direction ``sigma`` acts along,
and the variance it gives the heights of a local frame."""

from __future__ import annotations

import numpy as np

from .._shared._choices import Noise
from ..errors import InvalidParameterError

__all__ = ["Noise", "resolve_noise", "height_variance"]


def resolve_noise(noise, sensor, *, func: str) -> str:
    """The noise direction to use: `noise` checked, or its default.

    The default is ``'range'`` when a `sensor` is given (terrestrial scans), else ``'z'``;
    ``'range'`` needs the sensor.
    """
    if noise is None:
        noise = Noise.Z if sensor is None else Noise.RANGE
    noise = Noise.parse(noise, "noise", func=func)
    if noise == Noise.RANGE and sensor is None:
        raise InvalidParameterError(f"{func}: noise='range' needs the `sensor` position")
    return noise


def height_variance(frames, sigma, *, noise="z", points=None, sensor=None):
    """Variance of the local heights implied by measurement noise of std `sigma`.

    The local model's heights run along the frame axis n, while the instrument's noise runs
    along a direction d: z for range images and airborne data (``noise='z'``), the
    sensor-to-point ray for terrestrial scans (``'range'``), or n itself (``'normal'``,
    isotropic noise). The height noise then has variance ``sigma^2 (n . d)^2``; in the
    ``'z'`` frame with ``noise='z'`` this is sigma^2, as in the paper.

    Parameters
    ----------
    frames : (M, 3, 3) ndarray
        Local frames (rows e1, e2, n).
    sigma : float
    noise : {'z', 'range', 'normal'} or Noise
    points, sensor : ndarray, optional
        Point coordinates (M, 3) and sensor position, needed for ``'range'``.

    Returns
    -------
    (M,) ndarray
    """
    noise = Noise.parse(noise, "noise", func="height_variance")
    n = frames[:, 2, :]
    if noise == Noise.NORMAL:
        f = np.ones(n.shape[0])
    elif noise == Noise.Z:
        f = n[:, 2] ** 2
    else:
        d = points - np.asarray(sensor, dtype=np.float64)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        f = np.einsum("ij,ij->i", n, d) ** 2
    return sigma * sigma * np.maximum(f, 1e-12)
