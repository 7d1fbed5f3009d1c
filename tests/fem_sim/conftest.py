import logging

import numpy as np
import pytest

logging.getLogger("root").setLevel(logging.WARNING)  # FFCx JIT chatter
logging.getLogger().setLevel(logging.WARNING)


@pytest.fixture(scope="session")
def compiled():
    """``compiled(name)`` loads a C extension ("ogden", "tet", "ldlt") or skips with the reason
    when no C compiler is installed; with a compiler, a failed build fails the test.
    """
    import importlib
    import shutil
    import sysconfig

    from fem_sim import cext

    modules = {"ogden": "fem_sim.material.ogden_c", "tet": "fem_sim.solver.tet",
               "ldlt": "fem_sim.solver.ldlt"}

    def load(name: str):
        mod = importlib.import_module(modules[name]).load()
        if mod is None:
            cc = (sysconfig.get_config_var("CC") or "cc").split()[0]
            if shutil.which(cc) is None:
                pytest.skip(f"no C compiler ({cc}): the compiled {name} kernel cannot be "
                            f"built here, the solver uses its fallback")
            pytest.fail(f"{cc} is installed but the {name} extension did not build: "
                        f"{cext.why_unavailable(name)}")
        return mod

    return load


@pytest.fixture(scope="session")
def comm():
    from mpi4py import MPI

    return MPI.COMM_WORLD


def ogden_cauchy(stretches, c, m, K, volumetric):
    """Principal Cauchy stresses of the uncoupled Ogden law, written independently of fem_sim:

    W = sum_k c_k/m_k^2 (J^(-m_k/3) sum_i l_i^m_k - 3) + U(J), J = l1 l2 l3, so
    J sigma_i = l_i dW/dl_i = sum_k c_k/m_k (J^(-m_k/3) l_i^m_k - 1/3 J^(-m_k/3) sum_j l_j^m_k)
                + U'(J) J,     U'(J) J = K ln J (log) or K (J - 1) J (quadratic).
    """
    lam = np.asarray(stretches, dtype=float)
    J = lam.prod()
    s = np.zeros(3)
    for ck, mk in zip(c, m):
        s += ck / mk * J ** (-mk / 3) * (lam**mk - (lam**mk).sum() / 3)
    s += K * np.log(J) if volumetric == "log" else K * (J - 1) * J
    return s / J


@pytest.fixture
def cauchy():
    return ogden_cauchy
