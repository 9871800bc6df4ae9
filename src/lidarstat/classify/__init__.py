"""Per-point classes: HK surface types (seed 000), surface / edge / boundary (seed 003)."""

from ._covariance import FIELDS as COVARIANCE_CLASS_FIELDS
from ._covariance import (CovarianceClasses, CovarianceClassification, PointClass,
                          classify_covariance, covariance, estimate_plane_sigma)
from ._hk import SurfaceType, hk_surface_types

__all__ = ["SurfaceType", "hk_surface_types", "COVARIANCE_CLASS_FIELDS", "CovarianceClasses",
           "CovarianceClassification", "PointClass", "classify_covariance", "covariance",
           "estimate_plane_sigma"]
