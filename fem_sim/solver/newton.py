"""Newton's method on one load increment, with chord steps and a line search.

Each iteration is either a *chord step* (a back-solve with the last factorisation, kept while
it contracts |R| by ``chord_contraction`` or better) or a full Newton step (fresh Jacobian,
factorisation, line search). A Newton step after the first of an attempt is first tried by
GMRES preconditioned with that attempt's last factorisation (``near_iterations``; it is one
Newton step old, close enough to converge in a few iterations) and factorises only if GMRES
does not converge. This is Shamanskii's modified Newton with an adaptive switch: a
factorisation costs about ten back-solves plus a residual, so a chord step that reduces |R| by
5x is cheaper than a Newton step, and switching back to Newton as soon as contraction drops
keeps the robustness of full Newton.

An attempt fails (:class:`StepFailure`, with the reason) on NaN/inf, det F <= 0 at any
quadrature point, a linear-solver failure, a line search that cannot reduce the residual, or
too many iterations; the load stepper then retries or cuts back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fem_sim.solver import relaxation
from fem_sim.solver.equations import Equations
from fem_sim.solver.linear import LinearSolver
from fem_sim.solver.results import NewtonCounts, StepFailure
from fem_sim.solver.settings import SolverSettings

# An attempt that has not brought |R| below this fraction of its start in
# ``stall_iterations`` Newton steps is in Newton's slow phase (an indefinite tangent near a
# point load: the steps wander while the line search keeps them going); a converging one is
# many orders of magnitude below by then.
STALL_FRACTION = 1e-3


def is_stalled(iterations: int, r: float, r_start: float, limit: int) -> bool:
    """An attempt to give up: ``limit`` Newton iterations done (0: never) and |R| still above
    ``STALL_FRACTION`` of its start.
    """
    return limit > 0 and iterations == limit and r > STALL_FRACTION * r_start


@dataclass
class _Attempt:
    """One attempt at a load: |R|, the constraint gap, the tolerances, the steps so far."""

    lam: float
    r: float
    gap: float
    tol: float
    scale: float
    gap_tol: float
    history: list
    it: int = 0
    n_chord: int = 0
    chord: bool = False


class NewtonSolver:
    """Solves R(u; lam) = 0 from the current u (collective). Counts its chord steps."""

    def __init__(self, settings: SolverSettings, eqs: Equations, linear: LinearSolver):
        self.settings, self.eqs, self.linear = settings, eqs, linear
        self.attempt_iterations = 0  # Newton iterations of the last attempt, failed or not
        self.tolerance = self.start_residual = 0.0  # of the last attempt: |R| to reach, at u0
        self.relax = (relaxation.LocalRelaxation(eqs, settings.relax_rings,
                                                 settings.relax_max_nodes)
                      if settings.local_relaxation and relaxation.available(eqs) else None)
        self.reset()

    def reset(self) -> None:
        self.chord_steps = 0
        self.chord_rejected = 0
        self.near_steps = 0  # Newton steps solved with an older factorisation (no new one)
        if self.relax is not None:
            self.relax.reset()

    @property
    def relaxes(self) -> bool:
        """Whether each attempt starts with the hot-spot relaxation (one rank only)."""
        return self.relax is not None

    @property
    def local_iterations(self) -> int:
        return self.relax.iterations if self.relax is not None else 0

    def counts(self) -> NewtonCounts:
        """This simulation's Newton work so far."""
        return NewtonCounts(chord_steps=self.chord_steps, chord_rejected=self.chord_rejected,
                            near_steps=self.near_steps, local_iterations=self.local_iterations)

    @property
    def chord_allowed(self) -> bool:
        return self.settings.chord_contraction > 0 and self.linear.direct

    def solve(self, lam: float, history: list[float], first_order_start: bool,
              worse_than: float = math.inf) -> int:
        """Iterate to convergence at load ``lam``; returns the Newton iterations of this
        attempt (each a factorisation, unless solved on the last one: ``near_steps``).
        ``history`` receives |R| after every step. ``first_order_start``: u comes from a
        linear (or no) prediction. ``worse_than``: a start whose |R| exceeds it is given up
        before any Newton step (a guess worse than the alternative the stepper has).
        """
        s = self.settings
        self.attempt_iterations = 0
        a = self._start(lam, history)
        if a.r > worse_than:
            raise StepFailure(f"the predictor's guess at load {lam:.4g} is worse than the "
                              f"last state (|R| = {a.r:.3e} > {worse_than:.3e})")
        while True:
            self.attempt_iterations = a.it
            if a.r <= a.tol and a.gap <= a.gap_tol:
                return a.it
            if a.chord and a.gap <= a.gap_tol and a.n_chord < s.max_chord_steps:
                if self._chord(a):
                    continue
            if a.it == s.max_iterations:
                break
            if self._newton_step(a, first_order_start):
                return a.it
            if is_stalled(a.it, a.r, self.start_residual, s.stall_iterations):
                self.attempt_iterations = a.it
                raise StepFailure(f"Newton stalled at load {lam:.4g} (|R| = {a.r:.3e} after "
                                  f"{a.it} iterations, {self.start_residual:.3e} at the "
                                  "start)")
        raise StepFailure(f"Newton did not converge in {s.max_iterations} iterations at load "
                          f"{lam:.4g} (|R| = {a.r:.3e}, tolerance {a.tol:.1e})")

    def _start(self, lam: float, history: list[float]) -> _Attempt:
        """The attempt's start: |R| at the predictor (after the local relaxation of its hot
        spot, when that helps) and the tolerances.
        """
        s, eqs = self.settings, self.eqs
        if not eqs.update_points(tangent=False):
            raise StepFailure(f"det F <= 0 at the predictor (min det F = {eqs.min_J:.3g})")
        r = eqs.residual(lam)
        if not np.isfinite(r):
            raise StepFailure("NaN/inf in the residual at the predictor")
        gap = eqs.constraint_gap(lam)
        scale = max(lam * eqs.f_norm, r)
        tol = max(s.atol, s.rtol * scale)
        self.tolerance, self.start_residual = tol, r
        gap_tol = 1e-12 * max(1.0, eqs.cons.value_norm * lam)
        history.append(r)
        if self.relax is not None and r > tol and gap <= gap_tol and \
                self.relax.relax(lam, tol) > 0:
            # With the tangent: a Newton step nearly always follows (the relaxation leaves
            # the residual spread over the liver), and it then needs no separate pass.
            if not eqs.update_points(tangent=True):
                raise StepFailure(f"det F <= 0 after the local relaxation (min det F = "
                                  f"{eqs.min_J:.3g})")
            r = eqs.residual(lam)
            history.append(r)
        return _Attempt(lam=lam, r=r, gap=gap, tol=tol, scale=scale, gap_tol=gap_tol,
                        history=history)

    def _chord(self, a: _Attempt) -> bool:
        """A chord step (the last factorisation, no new one); False when it did not help.

        A chord step pays off only in Newton's fast phase: it contracts |R| about as much as
        the last Newton step did, so it is tried after a Newton step that cut |R| by
        ``chord_trigger`` or more, and kept up while each step contracts by
        ``chord_contraction`` (straight after the predictor or in Newton's slow phase it
        derails the next Newton step).
        """
        r_new = self._chord_step(a.lam, a.r)
        if r_new is None:
            self.chord_rejected += 1
            a.chord = False
            return False
        a.n_chord += 1
        self.chord_steps += 1
        a.history.append(r_new)
        a.chord = r_new <= self.settings.chord_contraction * a.r
        a.r = r_new
        return True

    def _newton_step(self, a: _Attempt, first_order_start: bool) -> bool:
        """One Newton step with line search; True when the attempt ends converged."""
        s, eqs = self.settings, self.eqs
        J = eqs.jacobian(lift=a.gap > 0)
        # Accurate linear solves keep Newton quadratic: loose (Eisenstat-Walker) tolerances
        # cost more Newton iterations (assembly + kernels) than they save.
        eta = s.krylov_rtol if a.gap > 0 else min(
            1e-2, max(s.krylov_rtol, 0.1 * a.tol / max(a.r, 1e-300)))
        if not self._solve_near(a.it, a.gap, J, eta):
            self.linear.solve(J, eqs.rhs, eqs.du, eta)
        # Round-off floor: |R| cannot decrease below ~eps * |F_int|, and that floor does not
        # shrink with a small increment (the stresses of a nearly undeformed state carry an
        # absolute round-off of ~eps * mu). A state this close to the full load's scale is
        # converged far beyond any tolerance that matters: it is kept if no step helps, and a
        # step that no longer halves |R| there ends the iteration.
        floor = a.r <= 1e-10 * max(a.scale, eqs.f_norm) and a.gap <= a.gap_tol
        alpha, r_new, accepted = self._line_search(a.lam, a.r, a.tol, a.gap > a.gap_tol,
                                                   a.it == 0 and first_order_start, floor)
        if not accepted and floor:
            a.it += 1
            return True
        if not accepted:
            why = ("det F <= 0" if eqs.min_J <= 0 else
                   "NaN/inf in the residual" if not np.isfinite(r_new) else
                   "no residual decrease")
            raise StepFailure(f"line search failed at load {a.lam:.4g}: {why} "
                              f"(|R| = {a.r:.3e})")
        a.it += 1
        stalled = floor and r_new > 0.5 * a.r
        a.chord = self.chord_allowed and alpha == 1.0 and r_new <= s.chord_trigger * a.r
        a.r = r_new
        a.gap = eqs.constraint_gap(a.lam)
        a.history.append(a.r)
        if stalled and a.gap <= a.gap_tol:
            return True
        if a.it >= 7 and a.r > a.history[0]:
            raise StepFailure(f"Newton is not converging at load {a.lam:.4g} (|R| = "
                              f"{a.r:.3e} after {a.it} iterations, {a.history[0]:.3e} at the "
                              "start)")
        return False

    def _solve_near(self, it: int, gap: float, J, eta: float) -> bool:
        """A later Newton step of this attempt solved by GMRES preconditioned with the
        attempt's own last factorisation (no new one), if that converges within
        ``near_iterations``; False: factorise as usual.

        Only after a Newton step of the same attempt: the factorisation is then one Newton
        step old, as for the Hermite tangents, which GMRES solves in ~3 iterations with it.
        A factorisation from the previous load step is not close enough (measured: plain
        chord steps from it diverge, GMRES needs 10-25 iterations, more than a
        factorisation costs).
        """
        if it == 0 or gap > 0 or self.settings.near_iterations <= 0 \
                or not self.linear.solves_near or not self.linear.has_factorization:
            return False
        ok = self.linear.solve_near(J, self.eqs.rhs, self.eqs.du, eta,
                                    self.settings.near_iterations)
        self.near_steps += ok
        return ok

    def _line_search(self, lam: float, r: float, tol: float, closing_gap: bool,
                     keep_full_step: bool, restore: bool) -> tuple[float, float, bool]:
        """U += alpha du with backtracking; returns (alpha, |R|, accepted). If nothing is
        accepted and ``restore``, u, the point values and R are put back as they were.

        Merit: the potential energy (Armijo along du, the natural merit function of
        hyperelasticity: full Newton steps that first raise |R| are still taken), or |R|.
        ``keep_full_step``: the first full Newton step from a linear (Euler) prediction is kept
        unless it is invalid (det F <= 0, NaN) or the residual explodes (> 1000x). Measured on
        the real liver under a point load: that step raises |R| and the energy ~16x and then
        converges quadratically; an Armijo test there costs 2-4 extra iterations. After a
        higher-order prediction, and for later steps, |R| or the energy must decrease (a kept
        30x rise was measured to cost 8 iterations).
        """
        s, eqs = self.settings, self.eqs
        u = eqs.u.vector
        u0 = u.copy()
        energy0 = eqs.energy(lam)
        slope = eqs.b.dot(eqs.du)  # dPi/dalpha at alpha = 0 (free rows; b is R)
        alpha, r_new, accepted = 1.0, math.inf, False
        for _ in range(8 if s.line_search else 1):
            u0.copy(u)
            u.axpy(alpha, eqs.du)
            ok = eqs.update_points(tangent=False)
            r_new = eqs.residual(lam) if ok else math.inf
            if ok and (not s.line_search or closing_gap or r_new <= tol
                       or (alpha == 1.0 and keep_full_step and r_new <= 1e3 * r)
                       or r_new <= (1.0 - 1e-4 * alpha) * r
                       or (slope < 0 and eqs.energy(lam) <= energy0 + 1e-4 * alpha * slope)):
                accepted = True
                break
            alpha *= 0.5
        if not accepted and restore:
            u0.copy(u)
            eqs.update_points(tangent=False)
            eqs.residual(lam)
        u0.destroy()
        return alpha, r_new, accepted

    def _chord_step(self, lam: float, r: float) -> float | None:
        """One chord step, u += J_old^-1 (-R): a back-solve with the last factorisation.

        Returns the new |R| if it contracted by ``chord_contraction``; otherwise restores the
        state (u, stresses, residual) and returns None.
        """
        eqs = self.eqs
        saved = eqs.save()
        eqs.set_rhs_to_minus_residual()
        r_new = math.inf
        if self.linear.back_solve(eqs.rhs, eqs.du):  # the operator is unchanged: no refactor
            eqs.u.vector.axpy(1.0, eqs.du)
            if eqs.update_points(tangent=False):
                r_new = eqs.residual(lam)
        if r_new <= self.settings.chord_contraction * r:
            return r_new
        eqs.restore(saved)
        return None
