"""The one place where Numba compilation defaults are set.

Every kernel uses ``@njit`` or ``@njit_parallel`` from here: ``cache=True`` so tests and the
CLI load compiled code from ``__pycache__`` instead of recompiling at every start,
``nogil=True`` so kernels can run in threads (Dask), ``fastmath=False`` because the
statistics rely on IEEE semantics (NaN propagation, every term rounded as written); a
small function of running sums over neighbours may take ``fastmath={"reassoc"}`` alone,
so that the compiler sums in vector lanes (``features/_quadric_kernels.py``).

A kernel called from another kernel is compiled for the argument types of the call
(:func:`one_signature`): constants count as plain ``int64``/``bool``/``float64`` and every
integer scalar (a ``prange`` index, an index read from an int32 array) as ``int64``, so
each helper is compiled once rather than once per constant, loop kind and integer width. Compilation is what a first run waits for.
"""

from __future__ import annotations

import contextlib
import sys

import numba
import numpy as np

_DEFAULTS = dict(cache=True, nogil=True, fastmath=False, error_model="numpy")


def _defer_blas_import():
    """Keep Numba's start from importing ``scipy.linalg`` for kernels that use no BLAS.

    When Numba loads its first kernel (compiled or cached) it imports its NumPy
    implementations, and ``numba.np.arraymath`` asks ``numba.np.linalg.ensure_blas`` at
    import whether a BLAS is there, which imports ``scipy.linalg`` (about 0.2 s: a
    sixth of a cached command's start). SciPy is a dependency, so the answer is known:
    that one question is answered yes without the import, and the check is put back at
    once, so a kernel that does use ``np.dot`` or ``np.linalg`` imports SciPy's BLAS
    when it is compiled, as before. Nothing changes if Numba's modules differ.
    """
    try:
        from numba.np import linalg
    except ImportError:  # pragma: no cover - another Numba layout
        return
    check = getattr(linalg, "ensure_blas", None)
    if check is None or "numba.np.arraymath" in sys.modules:
        return

    def answered():
        linalg.ensure_blas = check

    linalg.ensure_blas = answered


_defer_blas_import()


def njit(*args, **kwargs):
    """``numba.njit`` with lidarstat's defaults, one signature per argument types."""
    opts = {**_DEFAULTS, **kwargs}
    if args and callable(args[0]):
        return one_signature(numba.njit(**opts)(args[0]))
    decorate = numba.njit(*args, **opts)
    return lambda func: one_signature(decorate(func))


def njit_parallel(func):
    """``numba.njit(parallel=True)`` with lidarstat's defaults, one signature per types."""
    return one_signature(numba.njit(parallel=True, **_DEFAULTS)(func))


def kernel_array(a, dtype=np.float64):
    """`a` as a C-contiguous, writable array of `dtype`, the one array type kernels take.

    Numba types a read-only array apart from a writable one, so a kernel called with both
    (a view from ``np.broadcast_to``, a synthetic cloud's read-only truth arrays, a
    caller's read-only buffer) is compiled twice. This copies only an array that is
    read-only, of another dtype or not C-contiguous; a writable C array of `dtype` is
    returned as it is.
    """
    return np.require(a, dtype=dtype, requirements=["C", "W"])


def _call_type(ty):
    from numba.core import types

    ty = types.unliteral(ty)
    return types.int64 if isinstance(ty, types.Integer) else ty


def one_signature(dispatcher):
    """Compile `dispatcher`, when another kernel calls it, for plain argument types.

    Numba types a call from one kernel to another with the caller's types as they are: a
    constant argument as ``Literal[int](0)`` (one compilation per distinct constant),
    inside a ``prange`` loop the loop index as ``uint64`` where the same loop before the
    parallel rewrite typed it ``int64``, and an index read from an int32 neighbour array as
    ``int32`` where another caller passes an ``int64`` (each such helper compiled twice).
    Here a call types a constant as its plain type and every integer scalar as ``int64``;
    the caller converts the value (exact: no kernel of lidarstat takes an unsigned 64-bit
    scalar for its own sake, unsigned scalars in kernels are ``prange`` indices, always
    below 2**63, and no helper relies on the wrap-around of a narrower integer). Kernels
    that need a literal (``numba.literally``) cannot use this. Returns `dispatcher`.
    """
    typed = dispatcher.get_call_template

    def get_call_template(args, kws):
        return typed(tuple(_call_type(a) for a in args),
                     {k: _call_type(v) for k, v in kws.items()})

    dispatcher.get_call_template = get_call_template
    return dispatcher


def closure_cache(driver, functions):
    """Make the disk cache of a jitted closure over kernel `functions` work across processes.

    Numba keys the cache of a closure by the pickled contents of its cells; a jitted
    function in a cell pickles with a random per-process UUID and its Python function by
    value (with its globals), so the key changes in every process and the closure is
    compiled again each time (numba issue 6264). This gives `driver` (a dispatcher made
    with ``cache=True``) a cache keyed instead by the module, qualified name and source file
    hash of each of `functions`: stable across processes, distinct per set of kernels, and
    changed when a kernel's file is edited (as a plain cached function is recompiled when
    its own file changes). Returns `driver`.
    """
    import hashlib
    import inspect

    from numba.core.caching import FunctionCache

    parts = []
    for f in functions:
        py = getattr(f, "py_func", f)
        try:
            with open(inspect.getsourcefile(py), "rb") as fh:
                digest = hashlib.sha256(fh.read()).hexdigest()
        except (OSError, TypeError):  # no source file: never reuse a cached entry
            digest = repr(id(py))
        parts.append(f"{py.__module__}.{py.__qualname__}:{digest}")
    token = hashlib.sha256("|".join(parts).encode()).hexdigest()

    class _KeyedCache(FunctionCache):
        def _index_key(self, sig, codegen):
            code = hashlib.sha256(self._py_func.__code__.co_code).hexdigest()
            return (sig, codegen.magic_tuple(), (code, token))

    driver._cache = _KeyedCache(driver.py_func)
    return driver


@contextlib.contextmanager
def on_first_compile(callback):
    """Call ``callback()`` once, the first time a lidarstat kernel is compiled in the block.

    Numba signals ``numba:compile`` only on a cache miss (after looking in the disk cache),
    so this tells a run that waits for the compiler from one that loads cached code.
    """
    from numba.core import event

    class _Once(event.Listener):
        done = False

        def on_start(self, ev):
            if self.done:
                return
            py = getattr(ev.data.get("dispatcher"), "py_func", None)
            if getattr(py, "__module__", "").startswith("lidarstat"):
                self.done = True
                callback()

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", _Once()):
        yield


@contextlib.contextmanager
def dynamic_schedule(chunk=1):
    """Parallel kernels called in the block hand their ``prange`` iterations to the threads
    `chunk` at a time, as each thread is free, instead of one equal share per thread: for
    loops whose iterations cost unequal work (grid cells of unequal population), so that
    no thread waits for the other at the end. Results do not change (each iteration writes
    its own rows)."""
    old = numba.set_parallel_chunksize(chunk)
    try:
        yield
    finally:
        numba.set_parallel_chunksize(old)
