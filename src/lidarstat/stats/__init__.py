"""Vectorised hypothesis tests (chi-square, Wald, z, F, dip), sequential moments and densities."""

from ._binomial import binomial_test
from ._critical import (chi2_critical, chi2_pvalue, chi2_quantile, chi2_test, f_pvalue, f_test,
                        normal_pvalue, normal_quantile, t_critical, z_critical,
                        z_test_statistic)
from ._hotelling import hotelling_pvalue, hotelling_test
from ._moments import (DensityEstimate, SequentialMoments, density_estimate, dip_test,
                       sequential_moments, standard_moments)
from ._results import TestResult
from ._sar import LogDet, SARFit, sar_fit, sar_mean_surface, sar_trend, weights_matrix
from ._polynomial import PolynomialBasis, select_degree
from ._sar_tests import chow_test, likelihood_ratio_test, moran_test, sar_variance_test
from ._forward_search import deletion_residual_envelope, truncated_normal_variance
from ._tests import (f_test_paper, variance_test_paper, variance_test_satterthwaite, wald_test,
                     z_test)

__all__ = ["TestResult", "binomial_test", "z_critical", "t_critical", "chi2_critical", "chi2_quantile",
           "normal_quantile", "f_pvalue", "chi2_pvalue", "normal_pvalue", "hotelling_pvalue", "hotelling_test", "f_test", "chi2_test", "z_test_statistic", "variance_test_paper", "variance_test_satterthwaite", "wald_test",
           "z_test", "f_test_paper", "LogDet", "PolynomialBasis", "SARFit", "sar_fit",
           "sar_mean_surface", "sar_trend", "sar_variance_test", "select_degree", "weights_matrix",
           "moran_test", "likelihood_ratio_test", "chow_test", "deletion_residual_envelope",
           "truncated_normal_variance",
           "SequentialMoments", "sequential_moments", "standard_moments", "DensityEstimate", "density_estimate",
           "dip_test"]
