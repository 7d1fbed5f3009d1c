"""A liver's Green's function grown on request, for the manipulator.

``make liver`` solves the unit responses its load needs; a manipulator grasps anywhere. Given
the solver environment's python, :class:`GrownGreen` opens one solver process on the liver
(``fem_sim serve``'s ``green-open``: its tangent factorised once) and, when a load reaches
free surface nodes the small-strain file lacks, has them back-solved (``green-rows``) and
appended to the file's arrays in memory: each node is solved once, later calls find it.
With ``prefetch``, the process solves the rest of the free surface in the background, a few
nodes a request while nothing is asked (each request waits for at most one such chunk), so
that a patch grasped later is found solved; rows solved in the background are handed to the
file's arrays by the next call, on the caller's thread. numpy only on this side; the solver
process ends with the object.
"""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

import numpy as np


class GrownGreen:
    """The small-strain file ``lf`` (a :class:`~data_spec.linear_fields.LinearFields` of the
    directory ``data``, its liver's ``surface_nodes``) made to grow: ``grow(nodes)`` adds
    the unit responses of those of ``nodes`` on the free surface it lacks (True when rows
    were added since the last call, by it or in the background); ``lf.green`` and
    ``lf.green_nodes`` are then views of the grown arrays. ``seconds``: each request's wall
    time (the solves and their transfer); :meth:`prefetch` solves more in the background.
    """

    def __init__(self, lf, surface_nodes: np.ndarray, data, python: str):
        from surrogate.solver_process import SolverProcess

        self.lf, fixed = lf, lf.fixed(surface_nodes)
        lf.fixed_nodes = fixed   # no longer "the surface without a response"
        self.free = np.setdiff1d(surface_nodes, fixed)
        self._rows = np.empty((self.free.size,) + lf.green.shape[1:], np.float32)
        self._ids = np.empty(self.free.size, np.int64)
        self.n = self._solved = lf.green_nodes.size   # handed to lf / solved
        self._rows[:self.n], self._ids[:self.n] = lf.green, lf.green_nodes
        self._set()
        self._dir = tempfile.TemporaryDirectory(prefix="green-rows-")
        self.seconds: list[float] = []
        self._lock, self._stop, self._thread = threading.Lock(), threading.Event(), None
        self._asking = threading.Event()   # a caller waits: the background lets it go first
        self.prefetch_seconds = None
        try:
            self.solver = SolverProcess(python)
        except OSError as exc:
            self._dir.cleanup()
            raise ValueError(f"--solver {python}: cannot start it ({exc})") from None
        self.solver.send(["green-open", str(data)])
        if self.solver.answer():
            self.close()
            raise ValueError(f"{data}: the solver process cannot open the liver (its message "
                             "above)")

    def prefetch(self, order, chunk: int = 4) -> None:
        """Solve the free nodes of ``order`` in the background, in that order, ``chunk`` a
        request (those solved already skipped); once per object.
        """
        if self._thread is None:
            self._thread = threading.Thread(target=self._prefetch, daemon=True,
                                            args=(np.asarray(order, np.int64), chunk),
                                            name="green-prefetch")
            self._thread.start()

    @property
    def prefetching(self) -> bool:
        """Whether the background solves are still running."""
        return self._thread is not None and self._thread.is_alive()

    def _set(self) -> None:
        self.lf.green, self.lf.green_nodes = self._rows[:self.n], self._ids[:self.n]

    def _solve(self, missing: np.ndarray) -> None:
        """Solve ``missing`` into the rows after the solved ones (the lock held)."""
        out = Path(self._dir.name) / "rows.npy"
        self.solver.send(["green-rows", str(out), *map(str, missing.tolist())])
        if self.solver.answer():
            raise ValueError(f"the solver process could not solve nodes {missing[:5].tolist()}")
        k = missing.size
        self._rows[self._solved:self._solved + k] = np.load(out)
        self._ids[self._solved:self._solved + k] = missing
        self._solved += k

    def _prefetch(self, order: np.ndarray, chunk: int) -> None:
        """``order``'s free nodes, a chunk a request, until done or stopped (its wall
        seconds in ``prefetch_seconds`` when done).
        """
        t, order = time.perf_counter(), order[np.isin(order, self.free)]
        for i in range(0, order.size, chunk):
            while self._asking.is_set() and not self._stop.is_set():
                time.sleep(0.001)
            with self._lock:
                if self._stop.is_set():
                    return
                todo = np.setdiff1d(order[i:i + chunk], self._ids[:self._solved])
                try:
                    if todo.size:
                        self._solve(todo)
                except (ValueError, OSError):   # the caller's next request says why
                    return
        self.prefetch_seconds = time.perf_counter() - t

    def __call__(self, nodes) -> bool:
        nodes = np.intersect1d(np.asarray(nodes, np.int64).ravel(), self.free)
        self._asking.set()
        with self._lock:
            self._asking.clear()
            missing = np.setdiff1d(nodes, self._ids[:self._solved])
            if missing.size:
                t = time.perf_counter()
                self._solve(missing)
                self.seconds.append(time.perf_counter() - t)
            if self.n == self._solved:
                return False
            self.n = self._solved
            self._set()
            return True

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            self.solver.close()
        if self._thread is not None:
            self._thread.join()
        self._dir.cleanup()
