"""Load-step predictors: the starting guess of Newton at a new load fraction.

One interface, :class:`StepPredictor`: ``start()`` at the beginning of a simulation,
``converged(lam, newton_iterations)`` after every converged increment, ``predict(states, lam,
extrapolate)`` to set u for the next one; ``order`` says how good the last guess was meant to
be (0: the previous state; 1: linear), which the Newton loop uses to judge its first step.

* :class:`PreviousState` ("previous"): the last converged state.
* :class:`Extrapolation` ("extrapolate"): Lagrange extrapolation through the last converged
  states (up to quadratic); also what the others fall back to when displacements are
  prescribed.
* :class:`TangentIntegration` ("tangent"): u_last + the integral of the polynomial through
  the tangents du/dlam = J^-1 f of the last Newton iterations (one back-solve each with the
  last factorisation).
* :class:`Hermite` ("hermite", the default): at every converged state u_k the exact tangent
  du/dlam = J(u_k)^-1 f is computed (J assembled there, GMRES preconditioned with the last
  factorisation, starting from the polynomial's own estimate of it), and the next state is
  the polynomial of degree 2m-1 through the last m states and tangents. Its error falls as
  h^(2m) (tested); it needs a linear solver that can solve near a kept factorisation, and
  fixed (zero) constraints, else it acts as "tangent".
"""

from __future__ import annotations

import logging

import numpy as np

from fem_sim.solver.equations import Equations
from fem_sim.solver.linear import LinearSolver
from fem_sim.solver.results import StepFailure
from fem_sim.solver.settings import TANGENT_MAX_GMRES, TANGENT_RTOL, SolverSettings

log = logging.getLogger(__name__)

States = list[tuple[float, np.ndarray]]  # (load fraction, u) of the last converged states


class StepPredictor:
    """Interface (see the module docstring); subclasses override :meth:`_guess`."""

    def __init__(self, settings: SolverSettings, eqs: Equations, linear: LinearSolver):
        self.settings, self.eqs, self.linear = settings, eqs, linear
        self.order = 0
        self.error_exponent: int | None = None

    def start(self) -> None:
        """A new simulation from u = 0."""

    def converged(self, lam: float, newton_iterations: int) -> None:
        """U (the current state) converged at load ``lam``."""

    def predict(self, states: States, lam: float, extrapolate: bool = True) -> None:
        """Set u to the guess at load ``lam`` (collective). ``extrapolate=False``: retry from
        the last converged state. ``error_exponent``: q when the guess's error relative to the
        increment is known to scale as (increment)^q (the load stepper then sizes the next
        increment from it), else None.
        """
        self.order, self.error_exponent = 0, None
        if not (extrapolate and self._guess(states, lam)):
            self.eqs.set_state(states[-1][1])

    def _guess(self, states: States, lam: float) -> bool:
        """Set u to the guess and return True, or return False (then: the last state)."""
        return False


class PreviousState(StepPredictor):
    """Newton starts from the last converged state."""


class Extrapolation(StepPredictor):
    """Lagrange extrapolation through the last converged states."""

    def _guess(self, states: States, lam: float) -> bool:
        if len(states) == 1:
            return False
        lams = [st[0] for st in states]
        guess = np.zeros_like(states[-1][1])
        for i, (li, ui) in enumerate(states):
            w = 1.0
            for j, lj in enumerate(lams):
                if j != i:
                    w *= (lam - lj) / (li - lj)
            guess += w * ui
        self.eqs.set_state(guess)
        return True


class TangentIntegration(Extrapolation):
    """Better than extrapolating states, which overshoots in the stiffening early steps (fewer
    Newton iterations on the real liver in development runs).
    """

    def start(self) -> None:
        self._tangents: list[tuple[float, np.ndarray]] = []

    def converged(self, lam: float, newton_iterations: int) -> None:
        if newton_iterations == 0:
            # Converged on chord steps alone: the factorisation is from an older state, so the
            # next tangent would not belong to this one; do not mix it into the polynomial.
            self._tangents = []

    def _guess(self, states: States, lam: float) -> bool:
        eqs = self.eqs
        if not (len(states) > 1 and self.linear.has_factorization
                and eqs.cons.value_norm == 0.0):
            return super()._guess(states, lam)
        lam0, u0 = states[-1]
        eqs.set_rhs_to_load()
        if not self.linear.back_solve(eqs.rhs, eqs.du):
            return super()._guess(states, lam)
        # du/dlam at lam0 = J^-1 f_ext (J from the last Newton iteration). Keep the last few;
        # u(lam) = u0 + integral over [lam0, lam] of the polynomial through them (order 1:
        # Euler; 2, 3: the tangent's own change is extrapolated too).
        v = eqs.du.array_r.copy()
        tangents = [t for t in self._tangents if t[0] < lam0] + [(lam0, v)]
        self._tangents = tangents[-self.settings.predictor_order:]
        self.order = len(self._tangents)
        nodes = np.array([t[0] - lam0 for t in self._tangents])
        d = lam - lam0
        k = np.arange(nodes.size)
        V = nodes[None, :] ** k[:, None]  # V[k, i] = s_i^k
        w = np.linalg.solve(V, d ** (k + 1) / (k + 1))
        arr = eqs.u.x.array
        arr[:] = u0
        for wi, (_, vi) in zip(w, self._tangents):
            arr[: v.size] += wi * vi
        eqs.scatter()
        return True


class Hermite(TangentIntegration):
    """On PETSc's path too (tangents by GMRES with the kept MUMPS factorisation):
    ``bench/bench_predictor.py`` compares it with "tangent".
    """

    def start(self) -> None:
        super().start()
        self.points: list[tuple[float, np.ndarray, np.ndarray]] = []  # (lam, u, du/dlam)
        self.active = self.linear.solves_near and self.eqs.cons.value_norm == 0.0
        if self.active:
            self._record(0.0)

    def converged(self, lam: float, newton_iterations: int) -> None:
        super().converged(lam, newton_iterations)
        if self.active:
            self._record(lam)

    def _record(self, lam: float) -> None:
        """du/dlam = J(u)^-1 f_ext at the converged state u, kept with u. J is assembled at u;
        the solve is GMRES preconditioned with the last factorisation (a Newton iterate close
        to u), or a new factorisation if that fails. It starts from :meth:`tangent_guess`
        when that leaves a smaller residual than zero: the solve then only corrects it, to the
        same tolerance relative to |f_ext|.

        The guess is close to the tangent after the first steps but its error sits in the
        stiff modes under the load, so GMRES still runs, for fewer iterations.
        """
        eqs = self.eqs
        n = eqs.n_owned_dofs
        u = eqs.u.x.array[:n].copy()
        eqs.update_points(tangent=True)
        J = eqs.jacobian(lift=False)
        eqs.set_rhs_to_load()
        guess, rtol = self.tangent_guess(lam, u), TANGENT_RTOL
        if guess is not None:
            f_norm = eqs.rhs.norm()
            r0 = eqs.rhs.array_r[:n] - J.mult(guess)
            r0[eqs.cons.owned] = 0.0  # the guess is zero there (fixed dofs), as is f
            eqs.rhs.array[:n] = r0
            r0_norm = eqs.rhs.norm()
            if r0_norm < f_norm:
                rtol = TANGENT_RTOL * f_norm / max(r0_norm, 1e-300)  # >= 1: t = guess
            else:  # no better than zero: solve for the whole tangent
                eqs.set_rhs_to_load()
                guess = None
        # At u = 0 (lam = 0) J is the small-strain tangent, the same in every simulation of
        # this mesh, material and constraints: its factorisation may be kept across them.
        solve = self.linear.solve_recurring if lam == 0.0 else self.linear.solve
        if rtol < 1.0 and not self.linear.solve_near(J, eqs.rhs, eqs.du, rtol,
                                                      TANGENT_MAX_GMRES):
            try:
                solve(J, eqs.rhs, eqs.du, rtol)
            except StepFailure as exc:  # e.g. a singular tangent: predict without tangents
                log.debug("no tangent at load %.4g (%s)", lam, exc)
                self.points = []
                return
        t = eqs.du.array_r[:n].copy() if rtol < 1.0 else np.zeros(n)
        if guess is not None:
            t += guess
        self.points = (self.points + [(lam, u, t)])[-self.settings.predictor_order:]

    def tangent_guess(self, lam: float, u: np.ndarray) -> np.ndarray | None:
        """du/dlam at the new converged state (lam, u), estimated without a solve: the
        derivative at lam of the polynomial through the kept states and tangents and the new
        state (degree 2m for m kept points; exact for such a polynomial path, tested). None
        before the first kept point.
        """
        pts = [p for p in self.points if p[0] < lam]
        if not pts:
            return None
        w = hermite_weights([p[0] for p in pts], lam, derivative=True, value_at_end=True)
        return sum(w[2 * i] * ui + w[2 * i + 1] * ti
                   for i, (_, ui, ti) in enumerate(pts)) + w[-1] * u

    def _guess(self, states: States, lam: float) -> bool:
        if self.active and self.points:
            self.hermite(lam)
            return True
        return super()._guess(states, lam)

    def hermite(self, lam: float) -> None:
        """Set u(lam) from the Hermite polynomial through the kept points (degree 2m-1)."""
        pts = self.points
        m = len(pts)
        w = hermite_weights([p[0] for p in pts], lam)
        arr = self.eqs.u.x.array
        n = pts[-1][1].size
        arr[:n] = sum(w[2 * i] * ui + w[2 * i + 1] * ti for i, (_, ui, ti) in enumerate(pts))
        self.eqs.scatter()
        self.order = m
        if m >= 2 and m == self.settings.predictor_order:
            # Degree 2m - 1 through points spaced like the increment: the error is O(h^2m),
            # O(h^(2m-1)) relative to the increment itself. (Fewer points: the next guess will
            # have more, so this one's error says little about it.)
            self.error_exponent = 2 * m - 1


def hermite_weights(lams: list[float], lam: float, derivative: bool = False,
                    value_at_end: bool = False) -> np.ndarray:
    """Weights w of the polynomial p through values u_i and slopes t_i at ``lams`` (and, with
    ``value_at_end``, a value alone at ``lam``): p(lam), or p'(lam) with ``derivative``, is
    sum_i (w[2i] u_i + w[2i+1] t_i) (+ w[-1] u(lam)). Degree: one less than the conditions.
    Monomials in s = (x - lams[-1]) / (lam - lams[-1]), so the matrix stays well scaled.
    """
    lam0 = lams[-1]
    h = max(lam - lam0, 1e-300)
    k = 2 * len(lams) + int(value_at_end)
    p = np.arange(k)
    rows = []
    for li in lams:
        s = (li - lam0) / h
        rows.append(s ** p)
        rows.append(np.where(p > 0, p * s ** np.maximum(p - 1, 0), 0.0) / h)
    if value_at_end:
        rows.append(np.ones(k))
    target = p / h if derivative else np.ones(k)  # d/dlam or the value at s = 1
    return np.linalg.solve(np.array(rows).T, target)


PREDICTORS = {"previous": PreviousState, "extrapolate": Extrapolation,
              "tangent": TangentIntegration, "hermite": Hermite}


def make_predictor(settings: SolverSettings, eqs: Equations, linear: LinearSolver) -> StepPredictor:
    return PREDICTORS[settings.predictor](settings, eqs, linear)
