"""Type I/II/total error, confusion matrix and kappa on hand-computed examples."""

import numpy as np
import pytest

from lidarstat.classify import class_scores, filter_errors
from lidarstat.errors import InvalidParameterError


def test_filter_errors_hand_example():
    # a = 6 ground kept, b = 2 ground rejected, c = 1 object accepted, d = 3 objects rejected
    ref = np.array([1] * 8 + [0] * 4, bool)
    res = np.array([1] * 6 + [0] * 2 + [1] + [0] * 3, bool)
    e = filter_errors(res, ref)
    assert e.confusion.tolist() == [[6, 2], [1, 3]]
    assert e.type_i == pytest.approx(2 / 8)
    assert e.type_ii == pytest.approx(1 / 4)
    assert e.total == pytest.approx(3 / 12)
    po, pe = 9 / 12, (8 * 7 + 4 * 5) / 144
    assert e.kappa == pytest.approx((po - pe) / (1 - pe))


def test_class_scores_three_classes():
    ref = [2, 2, 2, 6, 6, 5]
    res = [2, 2, 6, 6, 5, 5]
    s = class_scores(res, ref)
    assert s.labels.tolist() == [2, 5, 6]
    assert s.confusion.tolist() == [[2, 0, 1], [0, 1, 0], [0, 1, 1]]
    assert s.accuracy == pytest.approx(4 / 6)
    assert s.recall[2] == pytest.approx(2 / 3) and s.precision[5] == pytest.approx(0.5)
    pe = (3 * 2 + 1 * 2 + 2 * 2) / 36
    assert s.kappa == pytest.approx((4 / 6 - pe) / (1 - pe))


def test_perfect_and_mismatched():
    assert filter_errors([1, 0, 1], [1, 0, 1]).kappa == pytest.approx(1.0)
    with pytest.raises(InvalidParameterError):
        filter_errors([1, 0], [1, 0, 1])
