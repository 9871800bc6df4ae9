"""Local models per point: weighted quadric (Taylor) fits and tested curvature."""

from ._curvature import FIELDS, CurvatureResult, curvature, estimate_sigma, test_curvature
from ._curvature_formulas import curvature_jacobian, curvatures, principal_jacobian
from ._quadric import FitStatus, QuadricFit, fit_quadrics

__all__ = ["FIELDS", "CurvatureResult", "FitStatus", "QuadricFit", "curvature",
           "curvature_jacobian", "curvatures", "estimate_sigma", "fit_quadrics",
           "principal_jacobian", "test_curvature"]
