"""A liver's Green's function grown on request, for the manipulator.

``make liver`` solves the unit responses its load needs; a manipulator grasps anywhere. Given
the solver environment's python, :class:`GrownGreen` opens one solver process on the liver
(``fem_sim serve``'s ``green-open``: its tangent factorised once) and, when a load reaches
free surface nodes the small-strain file lacks, has them back-solved (``green-rows``) and
appended to the file's arrays in memory: each node is solved once, later calls find it.
numpy only on this side; the solver process ends with the object.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np


class GrownGreen:
    """The small-strain file ``lf`` (a :class:`~data_spec.linear_fields.LinearFields` of the
    directory ``data``, its liver's ``surface_nodes``) made to grow: ``grow(nodes)`` adds
    the unit responses of those of ``nodes`` on the free surface it lacks (True when it
    added some); ``lf.green`` and ``lf.green_nodes`` are then views of the grown arrays.
    ``seconds``: each request's wall time (the solves and their transfer).
    """

    def __init__(self, lf, surface_nodes: np.ndarray, data, python: str):
        from surrogate.solver_process import SolverProcess

        self.lf, fixed = lf, lf.fixed(surface_nodes)
        lf.fixed_nodes = fixed   # no longer "the surface without a response"
        self.free = np.setdiff1d(surface_nodes, fixed)
        self._rows = np.empty((self.free.size,) + lf.green.shape[1:], np.float32)
        self._ids = np.empty(self.free.size, np.int64)
        self.n = lf.green_nodes.size
        self._rows[:self.n], self._ids[:self.n] = lf.green, lf.green_nodes
        self._set()
        self._dir = tempfile.TemporaryDirectory(prefix="green-rows-")
        self.seconds: list[float] = []
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

    def _set(self) -> None:
        self.lf.green, self.lf.green_nodes = self._rows[:self.n], self._ids[:self.n]

    def __call__(self, nodes) -> bool:
        nodes = np.intersect1d(np.asarray(nodes, np.int64).ravel(), self.free)
        missing = np.setdiff1d(nodes, self._ids[:self.n])
        if not missing.size:
            return False
        t, out = time.perf_counter(), Path(self._dir.name) / "rows.npy"
        self.solver.send(["green-rows", str(out), *map(str, missing.tolist())])
        if self.solver.answer():
            raise ValueError(f"the solver process could not solve nodes {missing[:5].tolist()}")
        rows = np.load(out)
        k = missing.size
        self._rows[self.n:self.n + k], self._ids[self.n:self.n + k] = rows, missing
        self.n += k
        self._set()
        self.seconds.append(time.perf_counter() - t)
        return True

    def close(self) -> None:
        self.solver.close()
        self._dir.cleanup()
