"""The solver's settings: one frozen dataclass, the single source of every default.

It lives in data_spec (standard library only) because it is part of the contract: the scene
schema's ``[solver]`` keys are the fields marked ``scene=True`` here (same defaults, same checks,
same documentation), and ``fem_sim``'s solver reads the whole record. The other fields are
Python-API knobs (``OgdenProblem(..., settings={...})``) that a scene does not expose, so adding
them never changes a scene's hash.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from data_spec.checks import is_int, is_num


def _setting(default: Any, doc: str, *, choices: tuple[str, ...] | None = None,
             lo: float | None = None, strict: bool = False, hi: float | None = None,
             scene: bool = False) -> Any:
    meta = {"doc": doc, "choices": choices, "lo": lo, "strict": strict, "hi": hi,
            "scene": scene}
    if isinstance(default, dict):
        return field(default_factory=lambda: dict(default), metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class SolverSettings:
    """Newton, load stepping and linear-solver settings of one :class:`OgdenProblem`."""

    # The default's cost in accuracy against tighter tolerances is measured in the price list
    # (docs/tradeoff_fem.md, tolerance rows) and by bench/bench_hard.py --settings: orders of
    # magnitude below the discretisation error of any mesh there.
    rtol: float = _setting(1e-6, "Newton relative residual tolerance: |R| <= rtol * "
                           "max(lambda |f|, |R| at the predictor)", lo=0.0, strict=True,
                           scene=True)
    atol: float = _setting(1e-10, "Newton absolute residual tolerance, N", lo=0.0, strict=True,
                           scene=True)
    max_iterations: int = _setting(25, "Newton iterations per attempt", lo=1, scene=True)
    max_cutbacks: int = _setting(8, "increment halvings allowed per output step", lo=0,
                                 scene=True)
    linear_solver: str = _setting("direct", "direct: a symmetric factorisation (which one: "
                                  "factorization); gamg: CG + GAMG with rigid-body modes",
                                  choices=("direct", "gamg"), scene=True)
    factorization: str = _setting(
        "auto", "direct: on one rank pardiso (float32 Cholesky by MKL PARDISO, METIS, "
        "GMRES-refined; MUMPS' LDL^T for a matrix that is not positive definite), single "
        "(float32 LDL^T by MUMPS) or double (float64); petsc (PETSc's MUMPS); auto: pardiso "
        "on one rank when MKL is installed, else single; petsc on several. The combinations "
        "with element, degree and ranks: data_spec/solver_rules.py",
        choices=("auto", "pardiso", "single", "double", "petsc"), scene=True)
    predictor: str = _setting(
        "hermite", "start of each load step: Hermite polynomial through the last converged "
        "states and their tangents, tangent integration, extrapolation of states, or the last "
        "state", choices=("hermite", "tangent", "extrapolate", "previous"), scene=True)
    pivoting: bool = _setting(False, "float32 LDL^T (factorization single) with MUMPS' "
                              "2x2 pivoting (SYM=2) instead of none (SYM=1, ~15 % faster; "
                              "an indefinite tangent still factorises, and a solve the "
                              "factors cannot give falls back to float64 with pivoting)")
    petsc_options: dict = _setting({}, "extra PETSc options for PETSc's solvers (factorization "
                                   "petsc, gamg); a pc_type here selects PETSc's path; "
                                   "ksp_max_it, ksp_rtol, ksp_atol win over the solver's own "
                                   "limits; an option PETSc never reads is reported once",
                                   scene=True)
    krylov_rtol: float = _setting(1e-10, "relative tolerance of each linear solve", lo=0.0,
                                  strict=True)
    max_krylov: int = _setting(0, "Krylov iterations before a solve counts as failed (0: the "
                               "path's own limit, 60 for the GMRES refinement of a "
                               "factorisation and 1000 for CG + GAMG; a scene raises it with "
                               "petsc_options ksp_max_it)", lo=0)
    predictor_order: int = _setting(3, "hermite: converged points used (1 = Euler); tangent: "
                                    "tangents used", lo=1)
    line_search: bool = _setting(True, "backtracking on the energy or |R| after each Newton "
                                 "step")
    chord_contraction: float = _setting(0.1, "keep back-solving with the last factorisation "
                                        "while |R| drops by this factor per step (0: no chord "
                                        "steps)", lo=0.0)
    chord_trigger: float = _setting(1e-2, "try chord steps after a Newton step that cut |R| "
                                    "this much", lo=0.0, strict=True)
    max_chord_steps: int = _setting(30, "chord steps per increment attempt", lo=0)
    near_iterations: int = _setting(8, "a Newton step after the first of an increment "
                                    "attempt: GMRES preconditioned with the attempt's last "
                                    "factorisation, up to this many iterations, before a new "
                                    "factorisation (0: always factorise)", lo=0)
    local_relaxation: bool = _setting(True, "one rank: before each load step's global "
                                      "Newton, relax the hot spot of the residual (largest "
                                      "nodal residuals and their neighbours) by a small local "
                                      "Newton iteration")
    relax_rings: int = _setting(2, "local relaxation: rings of neighbours added around the "
                                "nodes with the largest residuals", lo=0)
    relax_max_nodes: int = _setting(1000, "local relaxation: skipped when the hot spot has "
                                    "more nodes", lo=1)
    stall_iterations: int = _setting(10, "an increment attempt whose |R| is still above "
                                     "1e-3 of its start after this many Newton iterations is "
                                     "given up (retried or cut back as a failed one) instead "
                                     "of going on to max_iterations (0: never; measured in "
                                     "docs/solver_stalls.md)", lo=0)
    guess_guard: float = _setting(10.0, "with the local relaxation: an extrapolated guess "
                                  "whose |R| after it exceeds this many times the last "
                                  "state's at the new load (the load increment's |R|) is "
                                  "not iterated from: the increment starts from the last "
                                  "state instead (the first increment is cut back) (0: "
                                  "never; measured in docs/guess_guard.md)", lo=0.0)
    first_increment: float = _setting(0.25, "the first increment as a fraction of the first "
                                      "output step or of a tenth of the load, whichever is "
                                      "smaller (the stiffening start is taken in "
                                      "sub-increments that double after easy ones; later "
                                      "increments are sized by the predictor's error)",
                                      lo=0.0, strict=True, hi=1.0)

    @classmethod
    def from_dict(cls, values: dict | None, where: str = "settings") -> SolverSettings:
        """Settings from overrides of the defaults; ValueError listing every problem."""
        values = dict(values or {})
        found = problems(values, where)
        if found:
            raise ValueError("; ".join(found))
        return cls(**values)


# Values that were renamed: the message says the new name.
RENAMED = {("linear_solver", "mumps"): " ('mumps' is now 'direct'; factorization says which "
                                       "factorisation runs)"}


def fields(scene_only: bool = False) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(SolverSettings)
            if f.metadata["scene"] or not scene_only]


def default(f: dataclasses.Field) -> Any:
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def check(f: dataclasses.Field, v: Any) -> str | None:
    """None if ``v`` is a valid value of the field, else what was expected."""
    m = f.metadata
    kind = type(default(f))
    if m["choices"]:
        if v in m["choices"]:
            return None
        hint = RENAMED.get((f.name, v), "")
        return "one of " + ", ".join(map(repr, m["choices"])) + hint
    if kind is bool:
        return None if isinstance(v, bool) else "true or false"
    if kind is dict:
        if not isinstance(v, dict):
            return "a table of PETSc option -> value"
        for k, x in v.items():
            if not isinstance(x, (str, int, float, bool)):
                return f"a string/number/boolean value for PETSc option {k!r}"
        return None
    if kind is int and not is_int(v):
        return "an integer" + (f" >= {m['lo']}" if m["lo"] is not None else "")
    if kind is float and not is_num(v):
        return "a finite number"
    lo, hi = m["lo"], m["hi"]
    what = "an integer" if kind is int else "a number"
    if lo is not None and (v <= lo if m["strict"] else v < lo):
        upper = f" and <= {hi}" if hi is not None else ""
        return f"{what} {'>' if m['strict'] else '>='} {lo}{upper}"
    if hi is not None and v > hi:
        return f"{what} <= {hi}" + (f" and {'>' if m['strict'] else '>='} {lo}"
                                    if lo is not None else "")
    return None


def problems(values: dict, where: str = "settings") -> list[str]:
    """Every problem of a dict of overrides: unknown keys and invalid values."""
    known = {f.name: f for f in fields()}
    out = [f"{where}: unknown setting {k!r}; expected one of {sorted(known)}"
           for k in values if k not in known]
    for k, v in values.items():
        if k in known:
            why = check(known[k], v)
            if why:
                out.append(f"{where}.{k}: expected {why}, got {v!r}")
    return out
