"""Count Numba's outermost compilations (a kernel's helpers compile inside it).

Used by ``tests/conftest.py`` (every test process) and by the warm-up processes of
``tests/_compile_report.py``: the CPU seconds are the compiling thread's, which do not
grow when other jobs share the machine.
"""

from __future__ import annotations

import time


def count_compiles(totals, kernels):
    """Register a listener adding every outermost compilation's wall and CPU seconds and
    count to `totals` (keys ``seconds``, ``cpu``, ``count``) and ``[kernel and argument
    types, CPU seconds]`` to the list `kernels`."""
    from numba.core import event

    class _Outermost(event.Listener):
        depth = 0

        def on_start(self, ev):
            if self.depth == 0:
                self.start, self.cpu = time.perf_counter(), time.thread_time()
                py = getattr(ev.data.get("dispatcher"), "py_func", None)
                self.key = (f"{getattr(py, '__module__', '?')}.{getattr(py, '__qualname__', '?')}"
                            f"{ev.data.get('args', '')}")
            self.depth += 1

        def on_end(self, ev):
            self.depth -= 1
            if self.depth == 0:
                cpu = time.thread_time() - self.cpu
                totals["seconds"] += time.perf_counter() - self.start
                totals["cpu"] += cpu
                totals["count"] += 1
                kernels.append([self.key, round(cpu, 2)])

    event.register("numba:compile", _Outermost())
