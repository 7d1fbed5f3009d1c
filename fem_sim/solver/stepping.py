"""Load stepping: from the undeformed state through the requested load fractions.

Each increment starts from the predictor's guess. If Newton fails from an extrapolated guess,
the same increment is retried from the last converged state; if that fails too, the increment
is halved (up to ``max_cutbacks`` halvings per output step), and easy steps after a cut-back
let it grow again. Only the requested fractions are stored; nothing is ever returned for a
step that did not converge: a simulation that cannot go on stops with its reason and keeps
the steps it reached.
"""

from __future__ import annotations

import logging
import time

import numpy as np

from fem_sim.solver import blas
from fem_sim.solver.equations import Equations
from fem_sim.solver.linear import LinearSolver
from fem_sim.solver.newton import NewtonSolver
from fem_sim.solver.predictors import Predictor
from fem_sim.solver.results import Solution, StepFailure
from fem_sim.solver.settings import SolverSettings

log = logging.getLogger(__name__)

# An increment that would leave less than this fraction of itself before the output fraction
# goes to the output fraction instead. Tried at 0.5 in session 11 (the first step's
# sub-increments 0.25, 0.5, 0.25 of it become 0.25, 0.75): one factorisation fewer on the real
# liver's easy case, the phantoms, 2x force, P2 at 10-16 mm under a patch load (110 of the price
# list's 151 runs better, 12 worse), but under a nodal load on fine P2 meshes the Hermite
# polynomial through the unevenly spaced states (0, 0.025, 0.1) sent the second step astray:
# real liver P2 8 mm 14 -> 21-35 factorisations (25 -> 49-76 s), the 6 mm references 14 -> 20
# and 26. A cost that depends on luck is worse than one factorisation: back to a round-off
# guard.
STRETCH = 1e-3


class LoadStepper:
    """Runs one simulation through its load fractions with the pieces it is given."""

    def __init__(self, settings: SolverSettings, eqs: Equations, newton: NewtonSolver,
                 predictor: Predictor, linear: LinearSolver):
        self.settings, self.eqs, self.newton = settings, eqs, newton
        self.predictor, self.linear = predictor, linear

    def run(self, fractions: np.ndarray, gather) -> Solution:
        """Solve at every fraction from u = 0 (collective). ``gather()`` returns the current
        displacement at the source nodes (on rank 0) for storage. OpenBLAS runs on one thread
        meanwhile, except in MUMPS' factorisations (:mod:`fem_sim.solver.blas`).
        """
        with blas.threads(1):
            return self._run(fractions, gather)

    def _run(self, fractions: np.ndarray, gather) -> Solution:
        s, eqs = self.settings, self.eqs
        eqs.set_state(np.zeros_like(eqs.u.x.array))
        self.linear.reset()
        self.newton.reset()
        self.predictor.start()
        sol = Solution(fractions=fractions, displacement=None)
        stored = []
        states: list[tuple[float, np.ndarray]] = [(0.0, eqs.state())]
        lam, dlam = 0.0, self.first_increment(float(fractions[0]))
        last = float(fractions[-1])
        for target in fractions:
            t0 = time.perf_counter()
            iters, cutbacks, history, retry_plain = 0, 0, [], False
            dlam = min(dlam, target - lam) if dlam > 0 else target - lam
            try:
                while lam < target - 1e-14:
                    trial = min(lam + dlam, target)
                    if target - trial < STRETCH * dlam:
                        trial = target
                    self.predictor.predict(states, trial, extrapolate=not retry_plain)
                    try:
                        its = self.newton.solve(trial, history, self.predictor.order <= 1)
                    except StepFailure as exc:
                        iters += self.newton.attempt_iterations  # failed attempts cost too
                        if not retry_plain and len(states) > 1 and s.predictor != "previous":
                            # An extrapolated start can lie outside Newton's basin: retry the
                            # same increment from the last converged state before cutting back.
                            retry_plain = True
                            eqs.set_state(states[-1][1])
                            continue
                        retry_plain = False
                        cutbacks += 1
                        log.debug("step to %.4g failed (%s); cut back", trial, exc)
                        if cutbacks > s.max_cutbacks:
                            raise StepFailure(f"{exc}; gave up after {s.max_cutbacks} "
                                              "cut-backs") from None
                        eqs.set_state(states[-1][1])
                        dlam = 0.5 * (trial - lam)
                        self.linear.invalidate()
                        continue
                    iters += its
                    retry_plain = False
                    lam = trial
                    states = (states + [(lam, eqs.state())])[-3:]
                    if lam < last:
                        # Nothing is predicted after the last fraction: the Hermite predictor's
                        # tangent there (an assembly and a GMRES solve) would be thrown away.
                        self.predictor.converged(lam, its)
                    if its <= 3:
                        # An easy increment: let a cut-back or a small first increment grow
                        # (capped by the distance to the next output fraction).
                        dlam *= 2.0
            except StepFailure as exc:
                sol.status, sol.failure_reason = "failed", str(exc)
                eqs.set_state(states[-1][1])
                break
            sol.newton_iterations.append(iters)
            sol.residual_norms.append(history[-1])
            sol.residual_history.append(history)
            sol.cutbacks.append(cutbacks)
            sol.wall_time.append(time.perf_counter() - t0)
            stored.append(gather())
            dlam = max(dlam, 0.0)
            nxt = np.searchsorted(fractions, target, side="right")
            if nxt < fractions.size and not cutbacks:
                dlam = fractions[nxt] - target
        c = self.linear.counts
        sol.factorizations, sol.krylov_iterations = c.factorizations, c.krylov_iterations
        sol.back_solves, sol.double_fallbacks = c.back_solves, c.double_fallbacks
        sol.reused_factorizations = c.reused_factorizations
        sol.cholesky_fallbacks = c.cholesky_fallbacks
        sol.chord_steps, sol.chord_rejected = self.newton.chord_steps, self.newton.chord_rejected
        sol.near_steps = self.newton.near_steps
        sol.local_iterations = self.newton.local_iterations
        if eqs.disc.comm.rank == 0:
            sol.displacement = (np.stack(stored) if stored
                                else np.zeros((0, eqs.disc.n_nodes, 3)))
        return sol

    def first_increment(self, lam1: float) -> float:
        """The first load increment (later ones grow and shrink with Newton's work).

        At most ``first_increment`` of the first output step, and smaller when the
        small-strain solution says the step is strongly nonlinear: Ogden's law stiffens like
        stretch^(m - 2) (uniaxial tangent), so a linear guess over an increment whose
        small-strain displacement gradient reaches g misjudges the stiffness by about
        (m - 2) g. With t = du/dlam at u = 0 at hand (the Hermite predictor computes it at the
        start, with the factorisation the first Newton step needs anyway), the increment is
        capped where max(|m_k - 2|, 1) * max|grad t| * dlam = ``first_step_stiffening``.
        Measured on the real liver (``bench/bench_hard.py``, 14.6k nodes, P1): with the cap at
        1, 5x the nominal force (stiffening 8.4 over the first step) 31 factorisations instead
        of 41 and no cut-back, the other hard cases unchanged; but P2 at 12 mm 79 instead of
        34 (53 Newton iterations in step 2: the Hermite polynomial through the closely spaced
        states of a finely divided first step extrapolates badly over the next step). So the
        cap is off by default (``first_step_stiffening = 0``). Letting the rule also enlarge the
        first increment was worse: 2 more factorisations on the softest material, up to 13 more
        at 2x force.
        """
        s = self.settings
        dlam = lam1 * s.first_increment
        t = self.predictor.initial_tangent()
        if s.first_step_stiffening <= 0 or t is None:
            return dlam
        m = self.eqs.assembler.material.m
        rate = max(max(abs(mk - 2.0), 1.0) for mk in m) * self.eqs.max_gradient(t)
        if rate * dlam <= s.first_step_stiffening:
            return dlam
        return max(s.first_step_stiffening / rate, 1e-3 * lam1)
