"""Solver settings: :class:`data_spec.solver_settings.SolverSettings` (the one source of the
defaults, which the scene schema reads too) and the solver-internal constants.
"""

from __future__ import annotations

from data_spec.solver_settings import SolverSettings

__all__ = ["TANGENT_MAX_GMRES", "TANGENT_RTOL", "SolverSettings"]

# Tangents for the Hermite predictor: solved to this accuracy (the predictor's own error is
# ~1e-5 of the increment), by GMRES with the last factorisation as preconditioner, which is
# refactorised if GMRES needs more than TANGENT_MAX_GMRES iterations. Looser tangents save GMRES
# iterations and leave the converged states unchanged (they do not depend on the predictor
# beyond the Newton tolerance) until, around 1e-3, the worse guesses cost factorisations.
TANGENT_RTOL = 1e-6
TANGENT_MAX_GMRES = 12
