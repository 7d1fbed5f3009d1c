"""What one simulation returns (:class:`Solution`) and the one exception a failed increment
raises (:class:`StepFailure`). Control flags live in the pieces that use them, not here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

import numpy as np


class StepFailure(Exception):
    """An increment that did not converge; the message is the recorded reason."""


@dataclass
class LinearCounts:
    """Work of a linear solver in one simulation, counted by the solver itself."""

    factorizations: int = 0
    krylov_iterations: int = 0
    back_solves: int = 0       # back-solves with an existing factorisation (chord, predictor)
    double_fallbacks: int = 0  # float32 factorisations that had to be redone in float64
    cholesky_fallbacks: int = 0  # LDL^T after the Cholesky (not positive definite, mostly)
    reused_factorizations: int = 0  # kept from an earlier simulation (solve_recurring)


@dataclass
class NewtonCounts:
    """Work of the Newton loop in one simulation, counted by the loop itself."""

    chord_steps: int = 0       # accepted back-solves with an old factorisation
    chord_rejected: int = 0    # chord steps tried and undone (too little contraction)
    near_steps: int = 0        # Newton steps solved by GMRES on an older factorisation
    local_iterations: int = 0  # local Newton iterations of the hot-spot relaxation


@dataclass
class WorkCounts(NewtonCounts, LinearCounts):
    """Every work counter of one simulation: the one declaration that :class:`Solution`,
    the shards' solver statistics and the benchmarks read.
    """

    @classmethod
    def of(cls, linear: LinearCounts, newton: NewtonCounts) -> WorkCounts:
        return cls(**asdict(linear), **asdict(newton))

    def counts(self) -> dict[str, int]:
        return {f.name: int(getattr(self, f.name)) for f in fields(WorkCounts)}


@dataclass(kw_only=True)
class Solution(WorkCounts):
    """Result of :meth:`fem_sim.OgdenProblem.solve`. Arrays per *stored* output step; the
    work counters of :class:`WorkCounts` as attributes.
    """

    fractions: np.ndarray
    displacement: np.ndarray | None  # (n_done, n_nodes, 3) on the comm's rank 0, else None
    newton_iterations: list[int] = field(default_factory=list)
    residual_norms: list[float] = field(default_factory=list)
    cutbacks: list[int] = field(default_factory=list)
    increments: list[int] = field(default_factory=list)  # converged increments per step
    wall_time: list[float] = field(default_factory=list)
    residual_history: list[list[float]] = field(default_factory=list)
    # per stored step, the reaction (N) on each node set the solve was asked for (a tool's
    # grasped patch): the total internal force on its dofs, every rank
    reactions: list[np.ndarray] = field(default_factory=list)
    status: str = "ok"
    failure_reason: str = ""

    @property
    def n_done(self) -> int:
        return len(self.newton_iterations)

    @property
    def reaction(self) -> np.ndarray:
        """(n_done, n_sets, 3) N: :attr:`reactions` as one array."""
        n_sets = len(self.reactions[0]) if self.reactions else 0
        return np.asarray(self.reactions, dtype=np.float64).reshape(self.n_done, n_sets, 3) \
            if self.reactions else np.zeros((self.n_done, 0, 3))
