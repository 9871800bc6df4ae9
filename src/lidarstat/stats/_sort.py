"""Sorted values for the moment analyses and the dip test: ``np.sort`` by a radix sort.

Every window analysis of the moments classification sorts its heights (the sequential
moments read the prefixes of the sorted values, the dip test the sorted sample), five
passes over the cloud and the dip tests of every split and cluster, a large part of the
window passes' work. Sorting the doubles' bits by their digits
(:func:`._sort_kernels.radix_sort`) costs O(N) and gives the same array.
"""

from __future__ import annotations

import numpy as np

from .._shared._jit import kernel_array

__all__ = ["sort_values"]

#: Fewer values than this are sorted by ``np.sort`` (the radix passes' counts of 2,048
#: digits cost more than the comparisons then).
RADIX_MIN = 1536


def sort_values(values) -> np.ndarray:
    """``np.sort`` of 1-D `values` as float64, a new array.

    The same values in the same order as ``np.sort(np.asarray(values, float64))``; where
    -0.0 and 0.0 both occur (equal as numbers, so ``np.sort`` leaves their order to its
    partitioning) every -0.0 comes first. From :data:`RADIX_MIN` values on, a radix sort
    of the values' bits (O(N), :mod:`._sort_kernels`); values holding a NaN, and fewer
    values, go to ``np.sort``.

    Examples
    --------
    >>> sort_values([3.0, -1.5, 0.25, -1.5]).tolist()
    [-1.5, -1.5, 0.25, 3.0]
    """
    from ._sort_kernels import radix_sort

    x = kernel_array(np.asarray(values, dtype=np.float64).ravel())
    if x.size < RADIX_MIN:
        return np.sort(x)
    out = np.empty_like(x)
    if not radix_sort(x, out):
        return np.sort(x)
    return out
