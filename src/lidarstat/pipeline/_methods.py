"""The methods layer: one end-to-end entry per method, the same parameter names in all.

Every method is a function of the points and keyword parameters with one vocabulary
(``radius``/``k``, ``sigma``, ``noise``, ``sensor``, ``alpha``, ``<test>_alpha``,
``min_neighbors``, ``min_points``, ``rng``, ``progress``) returning a result with
``to_fields()``, ``summary()`` and ``params``:

=============  ===========================================  =============================
method         function                                     result
=============  ===========================================  =============================
curvature      :func:`lidarstat.features.curvature`         ``CurvatureResult``
jets           :func:`lidarstat.features.jets`              ``JetResult``
ridges         :func:`lidarstat.segment.ridges`             ``RidgeResult``
covariance     :func:`lidarstat.classify.covariance`        ``CovarianceClassification``
moments        :func:`lidarstat.classify.moments`           ``MomentsClassification``
=============  ===========================================  =============================

:func:`segmentation` runs ``lidarstat segment --method M`` from Python: the points go
through the method's whole chain (for ``covariance``: the classification, then the
region growing) and each parameter to the step that takes it.
"""

from __future__ import annotations

import inspect
from importlib import import_module

from ..errors import InvalidParameterError

__all__ = ["METHODS", "SEGMENTATIONS", "method_function", "segmentation"]

#: method name -> "module:function" of its end-to-end entry.
METHODS = {
    "curvature": "lidarstat.features:curvature",
    "jets": "lidarstat.features:jets",
    "ridges": "lidarstat.segment:ridges",
    "covariance": "lidarstat.classify:covariance",
    "moments": "lidarstat.classify:moments",
}

#: segmentation method -> the chain of ("module:function", fixed keywords) steps it runs,
#: in order; each step after the first also receives the previous step's result.
SEGMENTATIONS = {
    "sar": (("lidarstat.segment:segment_sar", {}),),
    "curvature": (("lidarstat.segment:segment_curvature", {}),),
    "covariance": (("lidarstat.classify:covariance", {"keep_neighbors": True}),
                   ("lidarstat.segment:segment_covariance", {})),
    "ridges": (("lidarstat.segment:ridges", {"creases": False}),
               ("lidarstat.segment:ridge_segments", {})),
}


def method_function(name: str):
    """The end-to-end function of method `name` (a key of :data:`METHODS`)."""
    if name not in METHODS:
        raise InvalidParameterError(f"unknown method {name!r}; one of "
                                    f"{', '.join(sorted(METHODS))}")
    module, func = METHODS[name].split(":")
    return getattr(import_module(module), func)


def _function(spec):
    module, func = spec.split(":")
    return getattr(import_module(module), func)


def _accepts(func) -> set[str]:
    """Keyword parameters of `func` (through a deprecation wrapper)."""
    sig = inspect.signature(inspect.unwrap(func))
    return {n for n, p in sig.parameters.items()
            if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}


def segmentation(points, *, method: str, **params):
    """Segment `points` by `method`, as ``lidarstat segment --method M`` does.

    Parameters
    ----------
    points : array_like, shape (N, 3)
    method : {"sar", "curvature", "covariance", "ridges"}
    **params
        Parameters of the method's steps, each routed to every step that takes it (the
        neighbourhood, noise and levels of the covariance classification and of its
        region growing, for instance). A name no step takes is refused.

    Returns
    -------
    Segmentation

    Examples
    --------
    >>> from lidarstat.synth import make_hip_roof_scene
    >>> scene = make_hip_roof_scene(rng=0)
    >>> seg = segmentation(scene.xyz, method="sar", radius=1.0)  # doctest: +SKIP
    """
    if method not in SEGMENTATIONS:
        raise InvalidParameterError(f"unknown segmentation method {method!r}; one of "
                                    f"{', '.join(sorted(SEGMENTATIONS))}")
    steps = [_function(s) for s, _ in SEGMENTATIONS[method]]
    fixed = [f for _, f in SEGMENTATIONS[method]]
    taken = [_accepts(f) - set(k) for f, k in zip(steps, fixed)]
    unknown = set(params) - set().union(*taken)
    if unknown:
        valid = sorted(set().union(*taken) - {"points", "xyz", "result", "ridge_result"})
        raise InvalidParameterError(
            f"segmentation(method={method!r}) takes no parameter "
            f"{', '.join(sorted(unknown))}; its parameters: {', '.join(valid)}")
    result = None
    for func, names, always in zip(steps, taken, fixed):
        kwargs = {**{k: v for k, v in params.items() if k in names}, **always}
        result = func(points, **kwargs) if result is None else func(points, result, **kwargs)
    return result
