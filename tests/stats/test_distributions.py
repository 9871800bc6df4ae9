"""The normal and chi-square tails of ``lidarstat.stats`` are SciPy's, without scipy.stats."""

import numpy as np
import pytest
from scipy import stats as st

from lidarstat.stats import _distributions as d

RNG = np.random.default_rng(7)
X = np.r_[RNG.uniform(-2, 80, 500), 0.0, -0.0, 1e-300, 1e300, np.inf, -np.inf, np.nan]
DF = np.r_[RNG.uniform(0.1, 60, 500), 0.0, -1.0, np.nan, 3.0, 1e-10, 2.5, 7.0]
Q = np.r_[RNG.uniform(0, 1, 500), 0.0, 1.0, -0.1, 1.1, np.nan, 1e-300, 0.5]


@pytest.mark.parametrize("ours, scipys, args", [
    (d.chi2_sf, st.chi2.sf, (X, DF)),
    (d.chi2_isf, st.chi2.isf, (Q, DF)),
    (d.chi2_ppf, st.chi2.ppf, (Q, DF)),
    (d.norm_sf, st.norm.sf, (X,)),
    (d.norm_isf, st.norm.isf, (Q,)),
    (d.norm_ppf, st.norm.ppf, (Q,)),
])
def test_same_values_as_scipy_stats_edges_included(ours, scipys, args):
    with np.errstate(all="ignore"):
        want = scipys(*args)
    np.testing.assert_array_equal(ours(*args), want)
    assert ours(*(a[3] for a in args)) == scipys(*(a[3] for a in args))


def test_scalars_give_floats():
    assert isinstance(d.chi2_sf(3.0, 2), float)
    assert d.chi2_sf(3.0, 2) == pytest.approx(np.exp(-1.5), rel=1e-15)
