"""What one simulation returns (:class:`Solution`) and the one exception a failed increment
raises (:class:`StepFailure`). Control flags live in the pieces that use them, not here.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class StepFailure(Exception):
    """An increment that did not converge; the message is the recorded reason."""


@dataclass
class LinearCounts:
    """Work of a linear solver in one simulation, counted by the solver itself."""

    factorizations: int = 0
    krylov_iterations: int = 0
    back_solves: int = 0
    double_fallbacks: int = 0  # float32 factorisations that had to be redone in float64
    cholesky_fallbacks: int = 0  # LDL^T after the Cholesky (not positive definite, mostly)
    reused_factorizations: int = 0  # kept from an earlier simulation (solve_recurring)


@dataclass
class Solution:
    """Result of :meth:`fem_sim.OgdenProblem.solve`. Arrays per *stored* output step."""

    fractions: np.ndarray
    displacement: np.ndarray | None  # (n_done, n_nodes, 3) on the comm's rank 0, else None
    newton_iterations: list[int] = field(default_factory=list)
    residual_norms: list[float] = field(default_factory=list)
    cutbacks: list[int] = field(default_factory=list)
    increments: list[int] = field(default_factory=list)  # converged increments per step
    wall_time: list[float] = field(default_factory=list)
    residual_history: list[list[float]] = field(default_factory=list)
    status: str = "ok"
    failure_reason: str = ""
    factorizations: int = 0
    krylov_iterations: int = 0
    back_solves: int = 0       # back-solves with an existing factorisation (chord, predictor)
    chord_steps: int = 0       # accepted back-solves with an old factorisation
    chord_rejected: int = 0    # chord steps tried and undone (too little contraction)
    near_steps: int = 0        # Newton steps solved by GMRES on an older factorisation
    double_fallbacks: int = 0  # float32 factorisations that had to be redone in float64
    cholesky_fallbacks: int = 0  # LDL^T after the Cholesky (not positive definite, mostly)
    reused_factorizations: int = 0  # kept from an earlier simulation (solve_recurring)
    local_iterations: int = 0  # local Newton iterations of the hot-spot relaxation

    @property
    def n_done(self) -> int:
        return len(self.newton_iterations)
