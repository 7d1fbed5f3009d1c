"""A liver's Green's function grown on request, for the manipulator.

``make liver`` solves the unit responses its load needs; a manipulator grasps anywhere. Given
the solver environment's python, :class:`GrownGreen` opens one solver process on the liver
(``fem_sim serve``'s ``green-open``: its tangent factorised once) and, when a load reaches
free surface nodes the small-strain file lacks, has them back-solved (``green-rows``) and
appended to the file's arrays in memory: each node is solved once, later calls find it.
With ``prefetch``, a second solver process, one thread, factorises the liver too and solves
the rest of the free surface in the background in blocks (a block of right-hand sides costs
a fraction of as many single solves), while the first stays free for what a caller asks: a
request never waits for the background's work. Rows solved in the background are handed to
the file's arrays by the next call, on the caller's thread. numpy only on this side; the
solver processes end with the object.
"""

from __future__ import annotations

import tempfile
import threading
import time
from pathlib import Path

import numpy as np

# nodes a background request solves at once, three right-hand sides each: a back-solve costs
# several times less in a block of dozens than alone (PARDISO, a validation liver's P2 mesh)
CHUNK = 16


class GrownGreen:
    """The small-strain file ``lf`` (a :class:`~data_spec.linear_fields.LinearFields` of the
    directory ``data``, its liver's ``surface_nodes``) made to grow: ``grow(nodes)`` adds
    the unit responses of those of ``nodes`` on the free surface it lacks (True when rows
    were added since the last call, by it or in the background); ``lf.green`` and
    ``lf.green_nodes`` are then views of the grown arrays. ``seconds``: each request's wall
    time (the solves and their transfer); :meth:`prefetch` solves more in the background.
    """

    def __init__(self, lf, surface_nodes: np.ndarray, data, python: str):
        self.lf, fixed = lf, lf.fixed(surface_nodes)
        lf.fixed_nodes = fixed   # no longer "the surface without a response"
        self.free = np.setdiff1d(surface_nodes, fixed)
        self._rows = np.empty((self.free.size,) + lf.green.shape[1:], np.float32)
        self._ids = np.empty(self.free.size, np.int64)
        self.n = self._solved = lf.green_nodes.size   # handed to lf / solved
        self._rows[:self.n], self._ids[:self.n] = lf.green, lf.green_nodes
        self._set()
        self._data, self._python = str(data), python
        self._dir = tempfile.TemporaryDirectory(prefix="green-rows-")
        self.seconds: list[float] = []
        self._lock, self._stop, self._thread = threading.Lock(), threading.Event(), None
        self._asking = threading.Lock()   # the first solver process, one request at a time
        self._background = None   # the prefetch's own solver process
        self.prefetch_seconds, self.prefetch_error = None, None
        try:
            self.solver = self._open(None)
        except ValueError:
            self._dir.cleanup()
            raise

    def _open(self, threads: int | None):
        """A solver process opened on the liver (``green-open``); ValueError if it cannot."""
        from surrogate.solver_process import SolverProcess

        try:
            solver = SolverProcess(self._python, threads=threads)
        except OSError as exc:
            raise ValueError(f"--solver {self._python}: cannot start it ({exc})") from None
        solver.send(["green-open", self._data])
        if solver.answer():
            solver.close()
            raise ValueError(f"{self._data}: the solver process cannot open the liver (its "
                             "message above)")
        return solver

    def prefetch(self, order, chunk: int = CHUNK) -> None:
        """Solve the free nodes of ``order`` in the background, in that order, ``chunk`` a
        request to a solver process of its own (those solved already skipped); once per
        object. ``prefetch_seconds`` when done, ``prefetch_error`` if it stopped.
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

    def _missing(self, nodes: np.ndarray) -> np.ndarray:
        with self._lock:
            return np.setdiff1d(nodes, self._ids[:self._solved])

    def _solve(self, solver, nodes: np.ndarray, name: str) -> None:
        """``nodes`` back-solved by ``solver`` and appended after the solved rows (those
        solved meanwhile by the other process skipped).
        """
        out = Path(self._dir.name) / f"{name}.npy"
        solver.send(["green-rows", str(out), *map(str, nodes.tolist())])
        if solver.answer():
            raise ValueError(f"the solver process could not solve nodes {nodes[:5].tolist()}")
        rows = np.load(out)
        with self._lock:
            new = ~np.isin(nodes, self._ids[:self._solved])
            k = int(new.sum())
            self._rows[self._solved:self._solved + k] = rows[new]
            self._ids[self._solved:self._solved + k] = nodes[new]
            self._solved += k

    def _prefetch(self, order: np.ndarray, chunk: int) -> None:
        """``order``'s free nodes, a chunk a request to the background's own solver process
        (one thread: the caller's keeps the other core), until done or stopped.
        """
        t, order = time.perf_counter(), order[np.isin(order, self.free)]
        try:
            self._background = self._open(threads=1)
            for i in range(0, order.size, chunk):
                todo = self._missing(order[i:i + chunk])
                if self._stop.is_set():
                    return
                if todo.size:
                    self._solve(self._background, todo, "background")
        except (ValueError, OSError) as exc:   # the window works on, solving on request
            self.prefetch_error = str(exc)
            return
        finally:
            if self._background is not None:
                self._background.close()
        self.prefetch_seconds = time.perf_counter() - t

    def __call__(self, nodes) -> bool:
        nodes = np.intersect1d(np.asarray(nodes, np.int64).ravel(), self.free)
        with self._asking:
            missing = self._missing(nodes)
            if missing.size:
                t = time.perf_counter()
                self._solve(self.solver, missing, "asked")
                self.seconds.append(time.perf_counter() - t)
        with self._lock:
            if self.n == self._solved:
                return False
            self.n = self._solved
            self._set()
            return True

    def close(self) -> None:
        self._stop.set()
        with self._asking:
            self.solver.close()
        if self._thread is not None:
            if self._background is not None:
                self._background.end()   # a request in flight is answered, then it ends
            self._thread.join()
        self._dir.cleanup()
