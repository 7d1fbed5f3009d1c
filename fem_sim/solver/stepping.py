"""Load stepping: from the undeformed state through the requested load fractions.

Increments are sized by the predictor's measured error (the Hermite predictor at full order:
:func:`next_increment`), independently of how far apart the requested fractions are: each
fraction is reached by equal increments no larger than that size, so a single answer asked
for in 1 or 2 fractions takes about the increments of a 10-fraction run, not one giant step.
Each increment starts from the predictor's guess. If Newton fails from an extrapolated guess,
the same increment is retried from the last converged state; if that fails too, the increment
is halved (up to ``max_cutbacks`` halvings per output step), and easy steps after a cut-back
let it grow again. Only the requested fractions are stored; nothing is ever returned for a
step that did not converge: a simulation that cannot go on stops with its reason and keeps
the steps it reached.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from fem_sim.solver import blas
from fem_sim.solver.equations import Equations
from fem_sim.solver.linear import LinearSolver
from fem_sim.solver.newton import NewtonSolver
from fem_sim.solver.predictors import StepPredictor
from fem_sim.solver.results import Solution, StepFailure, WorkCounts
from fem_sim.solver.settings import SolverSettings

log = logging.getLogger(__name__)

# An increment that would leave less than this fraction of itself before the output fraction
# goes to the output fraction instead: a round-off guard only. A larger value merges the
# stiffening start's sub-increments into unevenly spaced states, through which the Hermite
# polynomial extrapolates badly (docs/solver.md).
STRETCH = 1e-3

# Increment control from the Hermite predictor's own error (at full order): a guess off by
# about 1e-3 of the increment converges with one factorisation, one off by 1e-2 needs about
# three, and the error grows faster than the increment (as h^3.5-h^4.6), so the increment is
# sized to keep it near ERROR_TARGET.
ERROR_TARGET = 1e-3
ERROR_SHRINK = 3e-3
# An increment is shrunk for ERROR_SHRINK only if it needed at least this many factorisations
# (see next_increment).
COSTLY_FACTORIZATIONS = 3
# The first increment is taken from at most this fraction of the load, however large the first
# output step: from u = 0 the only guess is the small-strain (Euler) one. Measured there: first
# increments of 0.025 and 0.05 of the load converged with 2 factorisations, 0.075 needed 18,
# 0.125 and 0.25 failed (and were cut back, after ~20 Newton iterations each).
FIRST_STEP_LOAD = 0.1
MIN_INCREMENT = 1e-6  # a floor for the controller (cut-backs have their own limit)
# A guess whose residual is within this factor of Newton's tolerance counts as exact for the
# controller (a tiny load on the unit cube with atol dominating: the states carry 1e-4 noise
# and their "errors" halved the increment without end, found by test_mesh_convergence_orders).
NOISE = 1e3


@dataclass
class _Walk:
    """The load path so far: the last fraction reached, the next increment, the increment the
    predictor's measured error allows (once known), the last converged states.
    """

    lam: float
    dlam: float
    states: list
    last: float
    h_ok: float | None = None


@dataclass
class _Step:
    """The work toward one output fraction."""

    target: float
    t0: float
    iters: int = 0
    cutbacks: int = 0
    increments: int = 0
    retry_plain: bool = False
    history: list = field(default_factory=list)

    def record(self, sol: Solution) -> None:
        sol.newton_iterations.append(self.iters)
        sol.residual_norms.append(self.history[-1])
        sol.residual_history.append(self.history)
        sol.cutbacks.append(self.cutbacks)
        sol.increments.append(self.increments)
        sol.wall_time.append(time.perf_counter() - self.t0)


class LoadStepper:
    """Runs one simulation through its load fractions with the pieces it is given."""

    def __init__(self, settings: SolverSettings, eqs: Equations, newton: NewtonSolver,
                 predictor: StepPredictor, linear: LinearSolver):
        self.settings, self.eqs, self.newton = settings, eqs, newton
        self.predictor, self.linear = predictor, linear

    def run(self, fractions: np.ndarray, gather, reactions=()) -> Solution:
        """Solve at every fraction from u = 0 (collective). ``gather()`` returns the current
        displacement at the source nodes (on rank 0) for storage; at each stored fraction the
        reaction on each node set of ``reactions`` is kept too. OpenBLAS runs on one thread
        meanwhile, except in MUMPS' factorisations (:mod:`fem_sim.solver.blas`).
        """
        with blas.threads(1):
            return self._run(fractions, gather, reactions)

    def _run(self, fractions: np.ndarray, gather, reactions=()) -> Solution:
        eqs = self.eqs
        eqs.set_state(np.zeros_like(eqs.u.x.array))
        self.linear.reset()
        self.newton.reset()
        self.predictor.start()
        sol = Solution(fractions=fractions, displacement=None)
        stored = []
        w = _Walk(lam=0.0, dlam=self.first_increment(float(fractions[0])),
                  states=[(0.0, eqs.state())], last=float(fractions[-1]))
        for target in fractions:
            st = _Step(target=float(target), t0=time.perf_counter())
            w.dlam = min(w.dlam, target - w.lam) if w.dlam > 0 else target - w.lam
            try:
                while w.lam < target - 1e-14:
                    self._increment(w, st)
            except StepFailure as exc:
                sol.status, sol.failure_reason = "failed", str(exc)
                eqs.set_state(w.states[-1][1])
                break
            st.record(sol)
            stored.append(gather())
            if reactions:
                sol.reactions.append(np.array([eqs.reaction(n) for n in reactions]))
            w.dlam = max(w.dlam, 0.0)
            nxt = np.searchsorted(fractions, target, side="right")
            if nxt < fractions.size and not st.cutbacks:
                w.dlam = fractions[nxt] - target
        for name, value in WorkCounts.of(self.linear.counts, self.newton.counts()).counts().items():
            setattr(sol, name, value)
        if eqs.disc.comm.rank == 0:
            sol.displacement = (np.stack(stored) if stored
                                else np.zeros((0, eqs.disc.n_nodes, 3)))
        return sol

    @staticmethod
    def _trial(w: _Walk, target: float) -> float:
        """The load fraction the next increment tries."""
        if w.h_ok is not None:  # equal increments to the target, none above h_ok
            rest = target - w.lam
            return w.lam + rest / max(1, math.ceil(rest / w.h_ok - 1e-6))
        trial = min(w.lam + w.dlam, target)
        return target if target - trial < STRETCH * w.dlam else trial

    def _increment(self, w: _Walk, st: _Step) -> None:
        """One increment attempt toward ``st.target`` (collective): converged, retried from
        the last state, or cut back; StepFailure once the cut-backs are spent.
        """
        trial = self._trial(w, st.target)
        self.predictor.predict(w.states, trial, extrapolate=not st.retry_plain)
        q = self.predictor.error_exponent
        guess = self.eqs.state() if q else None
        factorizations = self.linear.counts.factorizations
        try:
            its = self.newton.solve(trial, st.history, self.predictor.order <= 1,
                                    self.guess_bound(w, st, trial))
        except StepFailure as exc:
            self._failed(w, st, trial, exc)
            return
        self._converged(w, st, trial, its, guess, q, factorizations)

    def guess_bound(self, w: _Walk, st: _Step, trial: float) -> float:
        """|R| above which the predictor's guess is given up for the last state: ``guess_guard``
        times the last state's |R| at ``trial``, which is the load increment's, (trial - lam)
        |f| (that state is converged at lam to within Newton's tolerance).

        On real livers under a point load (docs/guess_guard.md), a guess this far above the
        last state's |R| after the hot-spot relaxation sends Newton into its slow phase, where
        it stalls and the stepper retries from the last state anyway, after the stall's
        factorisations. At the first increment (from u = 0, whose Newton step is the linear
        guess itself) there is no other start: the increment is cut back at once, unless the
        cut-backs are spent (the last attempt is Newton's, and its failure the reason). Only
        where the relaxation runs (one rank): before it, the hot spot under the load dominates
        |R| even of a good guess, and Newton mends it in a step or two. Not with prescribed
        displacements (the last state then leaves a gap to close too).
        """
        g = self.settings.guess_guard
        last_chance = len(w.states) < 2 and st.cutbacks >= self.settings.max_cutbacks
        if g <= 0 or self.predictor.order == 0 or last_chance \
                or self.eqs.cons.value_norm > 0 or not self.newton.relaxes:
            return math.inf
        return g * (trial - w.lam) * self.eqs.f_norm

    def _failed(self, w: _Walk, st: _Step, trial: float, exc: StepFailure) -> None:
        s = self.settings
        st.iters += self.newton.attempt_iterations  # failed attempts cost too
        if not st.retry_plain and len(w.states) > 1 and s.predictor != "previous":
            # An extrapolated start can lie outside Newton's basin: retry the same increment
            # from the last converged state before cutting back.
            st.retry_plain = True
            self.eqs.set_state(w.states[-1][1])
            return
        st.retry_plain = False
        st.cutbacks += 1
        log.debug("step to %.4g failed (%s); cut back", trial, exc)
        if st.cutbacks > s.max_cutbacks:
            raise StepFailure(f"{exc}; gave up after {s.max_cutbacks} cut-backs") from None
        self.eqs.set_state(w.states[-1][1])
        w.dlam = 0.5 * (trial - w.lam)
        if w.h_ok is not None:
            w.h_ok = w.dlam
        self.linear.invalidate()

    def _converged(self, w: _Walk, st: _Step, trial: float, its: int, guess, q,
                   factorizations: int) -> None:
        st.iters += its
        st.increments += 1
        st.retry_plain = False
        h, w.lam = trial - w.lam, trial
        w.states = (w.states + [(w.lam, self.eqs.state())])[-3:]
        if guess is not None:
            # A guess Newton did not need to correct (no Newton step, or |R| within NOISE of
            # the tolerance) was good enough: its "error" is then the noise of the converged
            # states (they are exact only to the tolerance), never a reason to shrink.
            newton = self.newton
            exact = its == 0 or newton.start_residual <= NOISE * newton.tolerance
            err = 0.0 if exact else self.relative_error(guess, w.states[-2][1],
                                                         w.states[-1][1])
            costly = (self.linear.counts.factorizations - factorizations
                      >= COSTLY_FACTORIZATIONS)
            w.h_ok = max(next_increment(h, err, q, w.h_ok if w.h_ok is not None else w.dlam,
                                        costly), MIN_INCREMENT)
        if w.lam < w.last:
            # Nothing is predicted after the last fraction: the Hermite predictor's tangent
            # there (an assembly and a GMRES solve) would be thrown away.
            self.predictor.converged(w.lam, its)
        if its <= 3:
            # An easy increment: let a cut-back or a small first increment grow (capped by
            # the distance to the next output fraction).
            w.dlam *= 2.0

    def relative_error(self, guess: np.ndarray, before: np.ndarray, after: np.ndarray) -> float:
        """|after - guess| / |after - before| over the owned dofs (collective): the predictor's
        error relative to the increment it predicted.
        """
        n = self.eqs.n_owned_dofs
        local = np.array([np.sum((after[:n] - guess[:n]) ** 2),
                          np.sum((after[:n] - before[:n]) ** 2)])
        err2, inc2 = self.eqs.disc.comm.allreduce(local)
        return math.sqrt(err2 / inc2) if inc2 > 0 else 0.0

    def first_increment(self, lam1: float) -> float:
        """At most ``first_increment`` of the first output step or of FIRST_STEP_LOAD of the
        load, whichever is smaller; later increments grow with the predictor's measured error
        (:func:`next_increment`).
        """
        return min(lam1, FIRST_STEP_LOAD) * self.settings.first_increment


def next_increment(h: float, err: float, q: int, h_prev: float, costly: bool = True) -> float:
    """The largest increment the predictor's error allows, from an increment h whose guess was
    off by ``err`` (relative to the increment; it scales as h^q).

    Aimed at ERROR_TARGET, where Newton converges with one factorisation. The increment is
    made smaller (at most halved) only when the guess was off by more than ERROR_SHRINK and
    the increment was ``costly`` (COSTLY_FACTORIZATIONS = 3 or more factorisations: two
    increments cost at least two, so splitting a cheaper one cannot pay; measured on the
    softest material of bench/bench_hard.py, 14 -> 16 factorisations when cheap increments
    were split too);
    otherwise it grows towards the estimate, at most 2x, and never falls below ``h_prev`` (h
    may have been cut short by an output fraction: its small error says little about a larger
    increment, since the measured error grows more slowly than h^q from a short increment).
    """
    est = h * (ERROR_TARGET / err) ** (1.0 / q) if err > 0 else math.inf
    if err > ERROR_SHRINK and costly:
        return max(0.5 * h, est)
    return max(h_prev, h, min(est, 2.0 * h))
