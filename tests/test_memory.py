"""Large work arrays on ordinary pages (lidarstat._shared._memory)."""

import mmap

import numpy as np

from lidarstat._shared import _memory


def test_large_arrays_are_anonymous_mappings_and_behave_as_numpy_arrays():
    n = _memory.MIN_BYTES // 8 + 1
    a = _memory.empty((2, n))
    assert a.shape == (2, n) and a.dtype == np.float64 and a.flags.c_contiguous
    assert a.flags.writeable
    a[:] = np.arange(n)
    assert a[1, -1] == n - 1 and a[0].sum() == n * (n - 1) / 2
    base = a
    while isinstance(base, np.ndarray) and base.base is not None:
        base = base.base
    base = base.obj if isinstance(base, memoryview) else base
    assert isinstance(base, mmap.mmap) == _memory.SMALL_PAGES
    view = a[1]
    del a
    assert view[-1] == n - 1  # views keep the mapping alive


def test_small_and_empty_arrays_are_numpy_arrays():
    for shape, dtype in ((10, np.int32), ((0, 50), np.int32), (0, np.float64)):
        a = _memory.empty(shape, dtype=dtype)
        assert a.dtype == dtype and a.shape == np.empty(shape).shape and a.base is None
