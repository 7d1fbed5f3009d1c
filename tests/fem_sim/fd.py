"""Central-difference check of an assembled Jacobian against the assembled residual."""

import numpy as np

from fem_sim.solver import ldlt


def jacobian_fd_error(eqs, u0: np.ndarray, v: np.ndarray, h: float = 1e-6):
    """(largest |J v - FD(R; v)| on the free rows, largest |J v| there, R(u0)) for the
    Jacobian the solver factorises; ``v`` must vanish on the constrained dofs."""

    def residual(u):
        eqs.set_state(u)
        assert eqs.update_points(tangent=True)
        eqs.residual(0.0)
        return eqs.b.array.copy()

    fd = (residual(u0 + h * v) - residual(u0 - h * v)) / (2 * h)
    R0 = residual(u0)
    n = R0.size
    Jv = ldlt.csr(*eqs.jacobian(lift=False).csr()) @ v[:n]
    free = np.setdiff1d(np.arange(n), eqs.cons.owned)
    return np.abs(Jv[free] - fd[free]).max(), np.abs(Jv[free]).max(), R0
