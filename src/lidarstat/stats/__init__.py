"""Vectorised hypothesis tests (chi-square, Wald, z, F) returning statistics, p-values and decisions."""

from ._results import TestResult
from ._tests import (f_test_paper, variance_test_paper, variance_test_satterthwaite, wald_test,
                     z_test)

__all__ = ["TestResult", "variance_test_paper", "variance_test_satterthwaite", "wald_test",
           "z_test", "f_test_paper"]
