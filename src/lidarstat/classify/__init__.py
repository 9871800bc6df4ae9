"""Per-point classes: HK surface types (seed 000), surface / edge / boundary (seed 003),
moments classification and filter scores (seed 004)."""

from ..features import PointClass, SurfaceType, hk_surface_types
from ._covariance import BoundaryTest, CurvedTest, classify_covariance, covariance
from ._covariance_noise import estimate_plane_sigma
from ._covariance_result import FIELDS as COVARIANCE_CLASS_FIELDS
from ._covariance_result import CovarianceClasses, CovarianceClassification
from ._cycle import CycleChoice, ElevationRule, choose_cycle, skewness_balance_cycle
from ._outliers import low_outliers
from ._buildings import BUILDING_FIELDS, BuildingTests, building_tests
from ._moments import classify_moments, moments
from ._moments_options import MomentsMethod
from ._moments_result import ASPRS, MomentsClassification, MomentsStep
from ._roads import RoadRule
from ._scores import GROUND_CODES, ClassScores, FilterErrors, class_scores, filter_errors

__all__ = ["SurfaceType", "hk_surface_types", "COVARIANCE_CLASS_FIELDS", "CovarianceClasses",
           "CovarianceClassification", "PointClass", "classify_covariance", "covariance",
           "BoundaryTest", "CurvedTest",
           "estimate_plane_sigma", "ASPRS", "MomentsClassification", "MomentsStep",
           "moments", "classify_moments", "BUILDING_FIELDS", "BuildingTests", "building_tests", "MomentsMethod", "ElevationRule", "RoadRule",
           "low_outliers", "CycleChoice", "choose_cycle", "skewness_balance_cycle",
           "GROUND_CODES", "ClassScores", "FilterErrors", "class_scores", "filter_errors"]
