"""Filter errors (Sithole & Vosselman 2004), confusion matrices and Cohen's kappa."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameterError

__all__ = ["FilterErrors", "ClassScores", "filter_errors", "class_scores",
           "GROUND_CODES"]

#: ASPRS codes counted as bare earth when a classification is reduced to ground/object
#: (2 ground, 8 model key point, 9 water, 11 road surface).
GROUND_CODES = (2, 8, 9, 11)


def _kappa(cm: np.ndarray) -> float:
    n = cm.sum()
    if n == 0:
        return float("nan")
    po = np.trace(cm) / n
    pe = float((cm.sum(axis=0) * cm.sum(axis=1)).sum()) / n ** 2
    return float((po - pe) / (1 - pe)) if pe < 1 else float("nan")


@dataclass(frozen=True)
class FilterErrors:
    """Ground/object errors of a filter against a reference.

    Attributes
    ----------
    type_i : float
        Ground points classified as object, over reference ground points (b / (a + b)).
    type_ii : float
        Object points classified as ground, over reference object points (c / (c + d)).
    total : float
        Misclassified points over all points ((b + c) / n).
    kappa : float
        Cohen's kappa of the 2 x 2 table.
    confusion : (2, 2) ndarray of int64
        Rows reference (ground, object), columns result (ground, object): ``[[a, b], [c, d]]``.
    n : int
    """

    type_i: float
    type_ii: float
    total: float
    kappa: float
    confusion: np.ndarray
    n: int

    @classmethod
    def from_confusion(cls, confusion) -> "FilterErrors":
        """The errors of a (2, 2) confusion matrix (rows reference ground, object; columns
        result ground, object): counts of several tiles summed give the area's errors."""
        cm = np.asarray(confusion, dtype=np.int64).reshape(2, 2)
        (a, b), (c, d) = cm.tolist()
        n = a + b + c + d
        nan = float("nan")
        return cls(type_i=b / (a + b) if a + b else nan,
                   type_ii=c / (c + d) if c + d else nan,
                   total=(b + c) / n if n else nan, kappa=_kappa(cm), confusion=cm, n=n)

    def to_dict(self) -> dict:
        """JSON-ready dict (errors as fractions)."""
        return {"type_i": self.type_i, "type_ii": self.type_ii, "total": self.total,
                "kappa": self.kappa, "confusion": self.confusion.tolist(), "n": self.n,
                "rows": "reference ground, object", "columns": "result ground, object"}


def _check_pair(a, b, name_a, name_b):
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape or a.ndim != 1:
        raise InvalidParameterError(f"`{name_a}` (shape {a.shape}) and `{name_b}` (shape "
                                    f"{b.shape}) must be 1-D arrays of the same length")
    if a.size == 0:
        raise InvalidParameterError(f"`{name_a}` and `{name_b}` are empty")
    return a, b


def filter_errors(result_ground, reference_ground) -> FilterErrors:
    """Type I, Type II and total error of a ground filter (Sithole & Vosselman 2004).

    Parameters
    ----------
    result_ground, reference_ground : (N,) array_like of bool
        True where the filter / the reference says bare earth.

    Returns
    -------
    FilterErrors

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.array([1, 1, 1, 1, 0, 0], bool)
    >>> res = np.array([1, 1, 1, 0, 1, 0], bool)
    >>> e = filter_errors(res, ref)
    >>> e.type_i, e.type_ii, round(e.total, 4)
    (0.25, 0.5, 0.3333)
    """
    r, t = _check_pair(result_ground, reference_ground, "result_ground", "reference_ground")
    r = r.astype(bool)
    t = t.astype(bool)
    cm = np.array([[np.sum(t & r), np.sum(t & ~r)], [np.sum(~t & r), np.sum(~t & ~r)]],
                  dtype=np.int64)
    return FilterErrors.from_confusion(cm)


@dataclass(frozen=True)
class ClassScores:
    """Multi-class comparison.

    Attributes
    ----------
    labels : (K,) ndarray
        Class codes, sorted (union of both inputs).
    confusion : (K, K) ndarray of int64
        Rows reference, columns result.
    accuracy : float
        Overall agreement.
    kappa : float
        Cohen's kappa.
    precision, recall : dict
        Per class code.
    """

    labels: np.ndarray
    confusion: np.ndarray
    accuracy: float
    kappa: float
    precision: dict
    recall: dict

    @classmethod
    def from_confusion(cls, labels, confusion) -> "ClassScores":
        """The scores of a confusion matrix over `labels` (rows reference, columns
        result): counts of several tiles summed give the area's scores."""
        labels = np.asarray(labels)
        cm = np.asarray(confusion, dtype=np.int64)
        col = cm.sum(axis=0)
        row = cm.sum(axis=1)
        diag = np.diag(cm)
        nan = float("nan")
        prec = {int(c): (float(diag[i] / col[i]) if col[i] else nan)
                for i, c in enumerate(labels)}
        rec = {int(c): (float(diag[i] / row[i]) if row[i] else nan)
               for i, c in enumerate(labels)}
        return cls(labels=labels, confusion=cm, accuracy=float(diag.sum() / cm.sum()),
                   kappa=_kappa(cm), precision=prec, recall=rec)

    def to_dict(self) -> dict:
        """JSON-ready dict."""
        return {"labels": [int(v) for v in self.labels], "confusion": self.confusion.tolist(),
                "rows": "reference", "columns": "result", "accuracy": self.accuracy,
                "kappa": self.kappa,
                "precision": {str(k): v for k, v in self.precision.items()},
                "recall": {str(k): v for k, v in self.recall.items()}}


def class_scores(result, reference) -> ClassScores:
    """Confusion matrix, overall accuracy, Cohen's kappa, per-class precision and recall.

    Examples
    --------
    >>> s = class_scores([2, 2, 6, 6], [2, 2, 6, 2])
    >>> s.confusion.tolist(), s.accuracy, round(s.kappa, 4)
    ([[2, 1], [0, 1]], 0.75, 0.5)
    """
    r, t = _check_pair(result, reference, "result", "reference")
    labels = np.union1d(np.unique(r), np.unique(t))
    ri = np.searchsorted(labels, r)
    ti = np.searchsorted(labels, t)
    k = labels.size
    cm = np.bincount(ti * k + ri, minlength=k * k).reshape(k, k).astype(np.int64)
    return ClassScores.from_confusion(labels, cm)

