"""Vectorised hypothesis tests (chi-square, Wald, z, F) returning statistics, p-values and decisions."""

from ._results import TestResult
from ._sar import (LogDet, PolynomialBasis, SARFit, sar_fit, sar_mean_surface, select_degree,
                   weights_matrix)
from ._tests import (f_test_paper, variance_test_paper, variance_test_satterthwaite, wald_test,
                     z_test)

__all__ = ["TestResult", "variance_test_paper", "variance_test_satterthwaite", "wald_test",
           "z_test", "f_test_paper", "LogDet", "PolynomialBasis", "SARFit", "sar_fit",
           "sar_mean_surface", "select_degree", "weights_matrix"]
