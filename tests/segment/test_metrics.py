"""Hoover et al. (1996) measures on constructed cases and binary scores."""

import numpy as np
import pytest

from lidarstat.errors import InvalidParameterError
from lidarstat.segment import binary_scores, hoover


def test_perfect_segmentation_any_ids():
    truth = np.repeat([1, 2, 3, 0], [50, 30, 20, 10])
    pred = np.repeat([9, 4, 7, 0], [50, 30, 20, 10])
    s = hoover(pred, truth)
    assert (s.correct, s.over, s.under, s.missed, s.noise) == (3, 0, 0, 0, 0)
    assert s.correct_rate == 1.0
    assert sorted(map(tuple, s.correct_pairs.tolist())) == [(1, 9), (2, 4), (3, 7)]


def test_under_segmentation_and_noise():
    truth = np.repeat([1, 2, 3, 0], [40, 40, 20, 30])
    pred = np.repeat([1, 1, 2, 3], [40, 40, 20, 30])  # 1 and 2 merged; clutter segment 3
    s = hoover(pred, truth)
    assert s.correct == 1 and s.under == 2 and s.noise == 1 and s.missed == 0
    assert s.under_segmented == {1: [1, 2]}


def test_missed_and_tolerance():
    truth = np.repeat([1, 2], [100, 100])
    # Segment 2 holds 85 of region 2 plus 20 of region 1: correct at T=0.8, not at T=0.9.
    pred = np.r_[np.full(80, 1), np.full(20, 2), np.full(85, 2), np.zeros(15, int)]
    assert hoover(pred, truth, 0.8).correct == 2
    s = hoover(pred, truth, 0.9)
    assert s.correct == 0 and s.missed == 2 and s.noise == 2


def test_min_size_leaves_small_regions_out():
    truth = np.repeat([1, 2], [300, 50])
    pred = np.repeat([1, 2], [300, 50])
    s = hoover(pred, truth, min_points=200)
    assert s.n_truth == 1 and s.correct == 1 and s.noise == 0 and s.n_pred == 1


def test_random_relabelling_does_not_change_counts(rng):
    truth = rng.integers(0, 8, 2000)
    pred = np.where(rng.random(2000) < 0.9, truth, rng.integers(0, 8, 2000))
    perm = np.r_[0, rng.permutation(np.arange(1, 8)) + 10]
    a, b = hoover(pred, truth), hoover(perm[pred], truth)
    assert a.as_dict() == b.as_dict()


def test_bad_input():
    with pytest.raises(InvalidParameterError, match="tolerance"):
        hoover([1], [1], 0.5)
    with pytest.raises(InvalidParameterError, match="equal length"):
        hoover([1, 2], [1])


def test_binary_scores():
    s = binary_scores([1, 1, 1, 0, 0], [1, 1, 0, 1, 0])
    assert (s["tp"], s["fp"], s["fn"]) == (2, 1, 1)
    assert s["precision"] == pytest.approx(2 / 3) and s["f1"] == pytest.approx(2 / 3)
