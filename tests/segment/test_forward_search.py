"""Forward Search: rank-one updates equal refits, the search order, stopping under the null
and under contamination, block search, monitoring plots."""

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.report import plot_forward_search
from lidarstat.segment import forward_search


def _plane(rng, n=600, sigma=0.05):
    xy = rng.uniform(0, 20, (n, 2))
    y = 5 + 0.5 * xy[:, 0] - 0.2 * xy[:, 1] + rng.normal(0, sigma, n)
    return np.c_[np.ones(n), xy], y, xy


def test_order_and_updates_match_a_naive_search(rng):
    A, y, xy = _plane(rng, n=200)
    init = xy[:, 0] < 5
    res = forward_search(A, y, init)
    inside = init.copy()
    for step in range(40):  # naive: refit from scratch, recompute every deletion residual
        theta, *_ = np.linalg.lstsq(A[inside], y[inside], rcond=None)
        m, r = inside.sum(), A.shape[1]
        s2 = np.sum((y[inside] - A[inside] @ theta) ** 2) / (m - r)
        P = np.linalg.inv(A[inside].T @ A[inside])
        h = np.einsum("ij,jk,ik->i", A, P, A)
        d = np.abs(y - A @ theta) / np.sqrt(s2 * (1 + h))
        d[inside] = np.inf
        nxt = int(np.argmin(d))
        assert res.order[step] == nxt
        inside[nxt] = True
    full = np.ones(200, bool)
    theta_all, *_ = np.linalg.lstsq(A, y, rcond=None)
    res_all = forward_search(A, y, init, stop="f", alpha=1e-300)
    np.testing.assert_allclose(res_all.theta, theta_all, atol=1e-9)
    assert res_all.accepted.all() and full.sum() == res_all.m


def test_null_runs_to_the_end(rng):
    stops = 0
    for k in range(20):
        A, y, xy = _plane(np.random.default_rng(k), n=400)
        res = forward_search(A, y, xy[:, 0] < 6)
        stops += res.m < 400
    assert stops <= 3  # false stops are rare (envelope at 0.1%, F at 1%)


@pytest.mark.parametrize("block", [1, 8])
def test_contamination_is_left_out(rng, block):
    A, y, xy = _plane(rng, n=1500)
    roof = xy[:, 0] > 14          # a second plane meeting the first at x = 14
    y[roof] -= 1.0 * (xy[roof, 0] - 14)
    chimney = (np.hypot(xy[:, 0] - 6, xy[:, 1] - 10) < 1.0)
    y[chimney] += 1.0
    res = forward_search(A, y, (xy[:, 0] < 5) & ~chimney, block=block)
    good = ~roof & ~chimney
    assert res.accepted[good].mean() > 0.95
    assert not res.accepted[chimney].any()
    # the other plane enters only within a few sigma of the crease
    assert np.all(xy[res.accepted & roof, 0] < 14.4)
    assert res.stop_reason in ("residual", "f")


def test_monitoring_plot(rng, tmp_path):
    A, y, xy = _plane(rng, n=300)
    y[xy[:, 0] > 15] += 1
    res = forward_search(A, y, xy[:, 0] < 5)
    plot_forward_search(res, tmp_path / "fs.png")
    assert (tmp_path / "fs.png").read_bytes()[:4] == b"\x89PNG"


def test_bad_input(rng):
    A, y, xy = _plane(rng, n=50)
    with pytest.raises(InvalidParameterError, match="at least 4"):
        forward_search(A, y, np.arange(50) < 2)
    with pytest.raises(InvalidParameterError, match="same number"):
        forward_search(A, y[:10], np.arange(50) < 10)
    with pytest.raises(InvalidParameterError, match="'stop'"):
        forward_search(A, y, np.arange(50) < 10, stop="never")
