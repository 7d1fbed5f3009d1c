"""Solver settings: :class:`data_spec.solver_settings.SolverSettings` (the one source of the
defaults, which the scene schema reads too) and the solver-internal constants.
"""

from __future__ import annotations

from data_spec.solver_settings import SolverSettings

__all__ = ["TANGENT_MAX_GMRES", "TANGENT_RTOL", "SolverSettings"]

# Tangents for the Hermite predictor: solved to this accuracy (the predictor's own error is
# ~1e-5 of the increment), by GMRES with the last factorisation as preconditioner, which is
# refactorised if GMRES needs more than TANGENT_MAX_GMRES iterations. Measured on the real
# liver (14.6k nodes, easy case, dev run, 3 runs each side by side): 1e-6 instead of 1e-8 saves
# ~0.4 s of 12.4 (fewer GMRES iterations), the same Newton iterations, answers equal to 9e-11
# (the converged states do not depend on the predictor beyond the Newton tolerance); 1e-5
# saves no more; 1e-3 costs 3 factorisations more.
TANGENT_RTOL = 1e-6
TANGENT_MAX_GMRES = 12
