"""Local models per point: weighted quadric (Taylor) fits, tested curvature, jets and Monge forms.

The names are loaded on first use (PEP 562): ``lidarstat curvature`` imports the quadric
and curvature modules, not the covariance features, jets, cylinders or local planes.
"""

from importlib import import_module

#: Public name -> the module of this package that defines it (``COVARIANCE_FIELDS`` is
#: ``_covariance_result.FIELDS``).
_WHERE = {
    **dict.fromkeys(("Frame", "Noise", "Test", "Weight"), ".._shared._choices"),
    **dict.fromkeys(("curvature", "curvature_tests", "estimate_sigma"), "._curvature"),
    **dict.fromkeys(("FIELDS", "CurvatureResult"), "._curvature_result"),
    **dict.fromkeys(("fit_factor", "fit_height_variance", "fit_normals", "height_variance",
                     "noise_directions", "noise_factor", "resolve_noise", "sigma_from_fits"),
                    "._noise"),
    **dict.fromkeys(("point_spacing", "scale_ladder"), "._curvature_scale"),
    **dict.fromkeys(("OPTIMAL_K_MAX", "OPTIMAL_K_MIN", "covariance_features",
                     "covariance_frames"), "._covariance"),
    **dict.fromkeys(("COVARIANCE_FIELDS", "CovarianceResult", "EigenMode", "PointClass",
                     "eigen_features"), "._covariance_result"),
    **dict.fromkeys(("prefix_features", "tested_features", "tested_scale"),
                    "._covariance_scale"),
    "cylinder_test": "._cylinder",
    **dict.fromkeys(("SurfaceType", "hk_surface_types"), "._hk"),
    **dict.fromkeys(("BandwidthResult", "optimal_bandwidth"), "._bandwidth"),
    **dict.fromkeys(("curvature_jacobian", "curvatures", "principal_jacobian"),
                    "._curvature_formulas"),
    **dict.fromkeys(("MONGE_NAMES", "JetFit", "PrincipalDirections", "fit_jets",
                     "principal_directions"), "._jet_fit"),
    **dict.fromkeys(("CURVATURE_SCALE", "JetScaleCriterion", "radius_ladder"), "._jet_scale"),
    **dict.fromkeys(("JET_FIELDS", "JetResult", "jet_tests", "jets"), "._jets"),
    **dict.fromkeys(("FitStatus", "QuadricFit", "fit_quadrics"), "._quadric"),
    **dict.fromkeys(("PLANE_FIELDS", "AdaptiveBandwidth", "LocalPlaneFit", "geary_bandwidths",
                     "local_planes"), "._plane_regression"),
    **dict.fromkeys(("BandwidthCriterion", "BandwidthSelection", "select_plane_bandwidth"),
                    "._plane_bandwidth"),
}
_RENAMED = {"COVARIANCE_FIELDS": "FIELDS"}

__all__ = ["COVARIANCE_FIELDS", "OPTIMAL_K_MIN", "OPTIMAL_K_MAX", "CovarianceResult", "covariance_features", "covariance_frames", "eigen_features",
           "prefix_features", "tested_features", "tested_scale",
           "BandwidthResult", "optimal_bandwidth", "FIELDS", "CurvatureResult", "FitStatus", "QuadricFit", "curvature",
           "curvature_jacobian", "curvature_tests", "curvatures", "estimate_sigma",
           "fit_quadrics", "height_variance", "principal_jacobian", "fit_factor",
           "fit_height_variance", "fit_normals", "noise_directions", "noise_factor", "resolve_noise",
           "sigma_from_fits", "point_spacing", "scale_ladder",
           "PLANE_FIELDS", "AdaptiveBandwidth", "BandwidthCriterion", "BandwidthSelection", "LocalPlaneFit", "geary_bandwidths",
           "local_planes", "select_plane_bandwidth", "JET_FIELDS", "MONGE_NAMES",
           "CURVATURE_SCALE", "JetScaleCriterion", "radius_ladder",
           "JetFit", "JetResult",
           "PrincipalDirections", "fit_jets", "jet_tests", "jets", "principal_directions",
           "SurfaceType", "hk_surface_types", "cylinder_test", "PointClass", "EigenMode",
           "Noise", "Test", "Frame", "Weight"]


def __getattr__(name: str):
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(where, __name__), _RENAMED.get(name, name))
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
