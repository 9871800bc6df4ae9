"""Vectorised hypothesis tests (chi-square, Wald, z, F, dip), sequential moments and densities.

The names are loaded on first use (PEP 562), so that a command that needs only the
normal and chi-square tests does not import the SAR models, the forward search or
``scipy.stats``.
"""

from importlib import import_module

#: Public name -> the module of this package that defines it.
_WHERE = {
    "binomial_test": "_binomial",
    **dict.fromkeys(("chi2_critical", "chi2_pvalue", "chi2_quantile", "chi2_test", "f_pvalue",
                     "f_test", "normal_pvalue", "normal_quantile", "t_critical", "z_critical",
                     "z_test_statistic"), "_critical"),
    **dict.fromkeys(("hotelling_pvalue", "hotelling_test"), "_hotelling"),
    **dict.fromkeys(("DensityEstimate", "SequentialMoments", "density_estimate", "dip_test",
                     "moment_push", "moment_shape", "robust_frame", "sequential_moments",
                     "standard_moments"), "_moments"),
    "TestResult": "_results",
    "sort_values": "_sort",
    **dict.fromkeys(("chi2_isf_many", "chi2_isf_scalar", "chi2_sf_scalar", "gamma_q"),
                    "_tail_kernels"),
    **dict.fromkeys(("SARFit", "sar_fit", "sar_mean_surface", "sar_trend"), "_sar"),
    **dict.fromkeys(("LogDet", "weights_matrix"), "_sar_logdet"),
    **dict.fromkeys(("PolynomialBasis", "select_degree"), "_polynomial"),
    **dict.fromkeys(("chow_test", "likelihood_ratio_test", "moran_test", "sar_variance_test"),
                    "_sar_tests"),
    **dict.fromkeys(("deletion_residual_envelope", "truncated_normal_variance"),
                    "_forward_search"),
    **dict.fromkeys(("f_test_paper", "variance_test_paper", "variance_test_satterthwaite",
                     "wald_test", "z_test"), "_tests"),
}

__all__ = ["TestResult", "binomial_test", "z_critical", "t_critical", "chi2_critical", "chi2_quantile",
           "normal_quantile", "f_pvalue", "chi2_pvalue", "normal_pvalue", "hotelling_pvalue", "hotelling_test", "f_test", "chi2_test", "z_test_statistic", "variance_test_paper", "variance_test_satterthwaite", "wald_test",
           "z_test", "f_test_paper", "LogDet", "PolynomialBasis", "SARFit", "sar_fit",
           "sar_mean_surface", "sar_trend", "sar_variance_test", "select_degree", "weights_matrix",
           "moran_test", "likelihood_ratio_test", "chow_test", "deletion_residual_envelope",
           "truncated_normal_variance",
           "SequentialMoments", "sequential_moments", "standard_moments", "DensityEstimate", "density_estimate",
           "moment_push", "moment_shape", "robust_frame",
           "dip_test", "sort_values", "chi2_isf_many", "chi2_isf_scalar", "chi2_sf_scalar", "gamma_q"]


def __getattr__(name: str):
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{where}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(__all__)
