"""Local models per point: weighted quadric (Taylor) fits, tested curvature, jets and Monge forms."""

from .._shared._choices import Frame, Noise, Test, Weight
from ._curvature import curvature, curvature_tests, estimate_sigma
from ._curvature_result import FIELDS, CurvatureResult
from ._noise import (fit_factor, fit_height_variance, fit_normals, height_variance,
                     noise_directions, noise_factor, resolve_noise, sigma_from_fits)
from ._curvature_scale import point_spacing, scale_ladder
from ._covariance import OPTIMAL_K_MAX, OPTIMAL_K_MIN, covariance_features
from ._covariance_result import FIELDS as COVARIANCE_FIELDS
from ._covariance_result import CovarianceResult, EigenMode, PointClass, eigen_features
from ._covariance_scale import prefix_features, tested_features, tested_scale
from ._cylinder import cylinder_test
from ._hk import SurfaceType, hk_surface_types
from ._bandwidth import BandwidthResult, optimal_bandwidth
from ._curvature_formulas import curvature_jacobian, curvatures, principal_jacobian
from ._jet_fit import MONGE_NAMES, JetFit, PrincipalDirections, fit_jets, principal_directions
from ._jet_scale import CURVATURE_SCALE, JetScaleCriterion, radius_ladder
from ._jets import JET_FIELDS, JetResult, jet_tests, jets
from ._quadric import FitStatus, QuadricFit, fit_quadrics
from ._plane_regression import (PLANE_FIELDS, AdaptiveBandwidth, LocalPlaneFit,
                                geary_bandwidths, local_planes)
from ._plane_bandwidth import BandwidthCriterion, BandwidthSelection, select_plane_bandwidth

__all__ = ["COVARIANCE_FIELDS", "OPTIMAL_K_MIN", "OPTIMAL_K_MAX", "CovarianceResult", "covariance_features", "eigen_features",
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
