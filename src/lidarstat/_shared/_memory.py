"""Large work arrays on ordinary (4 KiB) pages instead of transparent huge pages.

NumPy advises the kernel to back every array of 4 MiB or more with transparent huge pages
(``madvise(MADV_HUGEPAGE)``). A huge page is taken from the free 2 MiB blocks of the
system, and on a virtual machine with free page reporting those are exactly the blocks
whose memory was handed back to the host: the first write to every one of them waits for
the host to back and clear 2 MiB again. On the 2-core VM of the benchmarks, filling 400
MB of fresh NumPy memory took 0.05-1.5 s (huge pages, depending on what the host had
reclaimed) against a steady 0.2-0.3 s on ordinary pages, and the kNN kernel writing its
1.8 GB of neighbourhood tables took 11.1-12.0 s of CPU into NumPy arrays against 8.3-8.9 s
into arrays on ordinary pages (alternating fresh processes). The arrays written once by
a kernel and then streamed (neighbour tables, kernel outputs, output fields) gain nothing
from huge pages, so :func:`empty` maps them as plain anonymous memory (``mmap``): no
NumPy global state is touched, and the memory returns to the system when the array (and
every view of it) is released, like any NumPy array's.

Set the environment variable ``LIDARSTAT_SMALL_PAGES=0`` to get plain ``numpy.empty``
arrays instead (same results; for timing comparisons).
"""

from __future__ import annotations

import mmap
import os

import numpy as np

#: Arrays smaller than this are ordinary ``numpy.empty`` arrays (NumPy's own threshold
#: for the huge-page advice).
MIN_BYTES = 4 << 20

SMALL_PAGES = os.environ.get("LIDARSTAT_SMALL_PAGES", "1") != "0"


def empty(shape, dtype=np.float64):
    """An uninitialised C-contiguous array, on ordinary pages when it is large.

    Parameters
    ----------
    shape : int or tuple of int
    dtype : data-type

    Returns
    -------
    ndarray
        Writable; its memory is an anonymous mapping when at least :data:`MIN_BYTES`
        (and :data:`SMALL_PAGES`), else from ``numpy.empty``.

    Examples
    --------
    >>> a = empty((3, 2_000_000), dtype=np.int32)
    >>> a[:] = 7
    >>> a.shape, a.dtype.name, int(a.sum()), a.flags.c_contiguous
    ((3, 2000000), 'int32', 42000000, True)
    """
    dtype = np.dtype(dtype)
    shape = (int(shape),) if np.ndim(shape) == 0 else tuple(int(s) for s in shape)
    count = 1
    for s in shape:
        count *= s
    nbytes = count * dtype.itemsize
    if not SMALL_PAGES or nbytes < MIN_BYTES:
        return np.empty(shape, dtype=dtype)
    return np.frombuffer(mmap.mmap(-1, nbytes), dtype=dtype, count=count).reshape(shape)


def physical_memory() -> int | None:
    """Bytes of physical memory of this machine, or None where the system does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def _malloc_trim():
    """glibc's ``malloc_trim``, or None where the C library is not glibc."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    return trim


_TRIM = _malloc_trim()


def release_freed() -> None:
    """Hand the memory freed so far back to the system (glibc ``malloc_trim(0)``).

    glibc serves a block from its heap once the block is below a threshold that it
    raises, up to 32 MiB, each time a mapped block is freed; the heap keeps what such
    blocks leave free between a method's steps, so the resident memory of a long run
    grows past what its live arrays hold. A method calls this between its steps (a few
    milliseconds); nothing happens where the C library is not glibc.
    """
    if _TRIM is not None:
        _TRIM(0)

