"""A solver process driven from the trainer's environment: ``python -m fem_sim serve`` under
the solver environment's python (:mod:`fem_sim.serve`), one command sent a line, one answer
read a line. What make liver (:mod:`surrogate.make_liver`) and the manipulator's grown
Green's function (:mod:`surrogate.green_rows`) talk to; numpy-free.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

# the variables that bound a process's BLAS / OpenMP threads
THREAD_LIMITS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


class SolverProcess:
    """``python -m fem_sim serve`` under ``python`` (the solver's environment): ``run(words)``
    sends a command and returns its exit code; its messages reach this process's standard
    error. The factorisation's threads take the cores (no OMP / OpenBLAS limit), or
    ``threads``.
    """

    def __init__(self, python: str, threads: int | None = None):
        env = {k: v for k, v in os.environ.items() if k not in THREAD_LIMITS}
        if threads:   # a process beside another's work: its solves on that many threads
            env.update(dict.fromkeys(THREAD_LIMITS, str(threads)))
        self.proc = subprocess.Popen([python, "-m", "fem_sim", "serve"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env=env)

    def send(self, words: list[str]) -> None:
        self.proc.stdin.write(json.dumps([str(w) for w in words]) + "\n")
        self.proc.stdin.flush()

    def answer(self) -> int:
        line = self.proc.stdout.readline()
        if not line:
            raise OSError(f"the solver process ended (exit code {self.proc.wait()})")
        out = json.loads(line)
        if "error" in out:
            print(f"fem_sim serve: {out['error']}", file=sys.stderr)
        return int(out["rc"])

    def end(self) -> None:
        """No more commands: the process ends (its teardown beside this process's work)."""
        if self.proc.stdin and not self.proc.stdin.closed:
            self.proc.stdin.close()

    def close(self) -> None:
        self.end()
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
