"""Which element runs with which degree, linear solver, factorisation and ranks: one table.

The scene check (a scene's ``[solver]``), the batch generator (with its ``--ranks-per-sim``,
before any file is written) and :class:`fem_sim.OgdenProblem` all ask :func:`problems`; the
solver asks :func:`linear_path` which linear-solver path a valid combination takes. A
combination that is not a row of :data:`ROUTES` is refused with the keys it names.
Standard library only.
"""

from __future__ import annotations

from dataclasses import dataclass

SERIAL_FACTORIZATIONS = ("pardiso", "single", "double")


@dataclass(frozen=True)
class Route:
    """One supported combination and the linear-solver path it takes."""

    element: str
    degrees: tuple[int, ...]
    quadrature_degrees: tuple[int, ...] | None  # None: any
    linear_solver: str
    factorizations: tuple[str, ...]
    one_rank: bool       # the path runs on one rank per simulation only
    petsc_pc: bool       # a petsc_options pc_type is allowed (it selects PETSc's solvers)
    path: str            # "serial", "petsc" or "gamg"
    what: str

    def matches(self, element, degree, qdeg, linear_solver, factorization, petsc_pc,
                ranks) -> bool:
        return (element == self.element and degree in self.degrees
                and (self.quadrature_degrees is None or qdeg in self.quadrature_degrees)
                and linear_solver == self.linear_solver
                and factorization in self.factorizations
                and (self.petsc_pc or not petsc_pc)
                and (ranks is None or ranks == 1 or not self.one_rank))


# First match wins: on one rank without a PETSc pc_type, "auto" takes the serial path.
ROUTES = (
    Route("lagrange", (1, 2), None, "direct", ("auto",) + SERIAL_FACTORIZATIONS, True, False,
          "serial", "MKL PARDISO's float32 Cholesky (pardiso; auto with MKL) or "
          "MUMPS' LDL^T through its C interface (single: float32, double: float64; auto "
          "without MKL)"),
    Route("lagrange", (1, 2), None, "direct", ("auto", "petsc"), False, True, "petsc",
          "PETSc's KSP with MUMPS' Cholesky (auto on several ranks, or a pc_type in "
          "petsc_options)"),
    Route("lagrange", (1, 2), None, "gamg", ("auto",), False, True, "gamg",
          "CG + GAMG with the rigid-body near-nullspace"),
    Route("anp", (1,), (1,), "direct", ("auto",) + SERIAL_FACTORIZATIONS, True, False,
          "serial", "averaged nodal pressure: P1, one quadrature point, the serial "
          "factorisation"),
)


def default_quadrature(degree: int) -> int:
    """The quadrature degree when none is given: 1 for P1 (one point: FEBio's tet4), 2 for P2
    (enough for its linear strains in the reference tests).
    """
    return 1 if degree == 1 else 2


def _find(element, degree, qdeg, linear_solver, factorization, petsc_options, ranks):
    pc = "pc_type" in (petsc_options or {})
    for r in ROUTES:
        if r.matches(element, degree, qdeg, linear_solver, factorization, pc, ranks):
            return r
    return None


def table() -> str:
    """The supported combinations, one line each (for error messages and the docs)."""
    lines = []
    for r in ROUTES:
        q = "" if r.quadrature_degrees is None else \
            f", quadrature_degree {'/'.join(map(str, r.quadrature_degrees))}"
        lines.append(f"element {r.element!r}, degree {'/'.join(map(str, r.degrees))}{q}, "
                     f"linear_solver {r.linear_solver!r}, factorization "
                     f"{'/'.join(r.factorizations)}, "
                     f"{'one rank' if r.one_rank else 'any ranks'}: {r.what}")
    return "\n".join(lines)


def problems(element: str, degree: int, quadrature_degree: int | None, linear_solver: str,
             factorization: str, petsc_options: dict | None, ranks: int | None = None,
             where: str = "solver") -> list[str]:
    """[] if the combination is a row of the table (for some rank count when ``ranks`` is
    None), else one message naming every key of the combination and the supported rows.
    """
    qdeg = quadrature_degree if quadrature_degree is not None else default_quadrature(degree)
    if _find(element, degree, qdeg, linear_solver, factorization, petsc_options,
             ranks) is not None:
        return []
    pc = "pc_type" in (petsc_options or {})
    said = (f"{where}.element = {element!r}, degree = {degree!r}, quadrature_degree = "
            f"{qdeg!r}, linear_solver = {linear_solver!r}, factorization = "
            f"{factorization!r}" + (f", petsc_options.pc_type = "
                                    f"{petsc_options['pc_type']!r}" if pc else "")
            + (f" on {ranks} ranks per simulation (--ranks-per-sim)" if ranks else ""))
    return [f"{said}: not a supported combination; supported:\n  "
            + table().replace("\n", "\n  ")]


def scene_problems(sv: dict, ranks: int | None = None) -> list[str]:
    """:func:`problems` of a scene's normalised ``[solver]`` table."""
    return problems(sv.get("element", "lagrange"), sv["degree"], sv.get("quadrature_degree"),
                    sv["linear_solver"], sv["factorization"], sv["petsc_options"], ranks)


def linear_path(linear_solver: str, factorization: str, petsc_options: dict | None,
                ranks: int, element: str = "lagrange", degree: int = 1,
                quadrature_degree: int | None = None) -> str:
    """"serial", "petsc" or "gamg": the path a valid combination takes on ``ranks`` ranks.
    ValueError (naming the keys) for an unsupported one.
    """
    qdeg = quadrature_degree if quadrature_degree is not None else default_quadrature(degree)
    r = _find(element, degree, qdeg, linear_solver, factorization, petsc_options, ranks)
    if r is None:
        raise ValueError("; ".join(problems(element, degree, quadrature_degree, linear_solver,
                                            factorization, petsc_options, ranks,
                                            where="settings")))
    return r.path
