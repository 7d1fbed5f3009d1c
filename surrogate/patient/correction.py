"""The correction of a patient's base (:mod:`surrogate.patient`): kernel ridge regression of
the residual of the K FE fields against the base on the load, with the reciprocity readings
of the K simulations (:class:`Sensors`), its setting chosen by nested cross-validation over
whole simulations.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from surrogate.metrics import mee
from surrogate.tuning import simulation_folds

LENGTHS = (10.0, 20.0, 40.0, 80.0, 160.0)   # mm: the kernel's length scales tried
DECAYS = ("gauss", "exp")                    # how it falls with the load points' distance d:
                                             # exp(-d^2 / 2 l^2), or exp(-d / l)
RIDGES = (1e-3, 1e-2, 0.1, 0.3, 1.0, 3.0, 10.0)   # relative to the kernel's mean diagonal
BETAS = (0.0, 1.0)                           # weight of the quadratic force term


def _products(a: tuple, b: tuple) -> tuple:
    """What the kernel needs of cases a, b = (load points (n, 3) mm, forces (n, 3) N,
    population fields (n, m) mm, reciprocity readings (n, K) mm): squared distances, force,
    field and readings inner products.
    """
    (xa, fa, ua, sa), (xb, fb, ub, sb) = a, b
    return ((xa[:, None, :] - xb[None, :, :]) ** 2).sum(-1), fa @ fb.T, ua @ ub.T, sa @ sb.T


def _combined(p: tuple, length: float, beta: float, mix: float, decay: str, gamma: float,
              scales: tuple) -> np.ndarray:
    """(na, nb): (1 - mix) x a decay in the load points' distance (``DECAYS``) times
    f.f' + beta (f.f')^2, plus mix x the population fields' inner product, plus gamma x the
    reciprocity readings' (``scales``: the force's, the fields' and the readings' scales).
    """
    d2, ff = p[0], p[1] / scales[0] ** 2
    uu, ss = p[2] / scales[1] ** 2, p[3] / scales[2] ** 2
    near = np.exp(-d2 / (2.0 * length ** 2)) if decay == "gauss" else \
        np.exp(-np.sqrt(np.maximum(d2, 0.0)) / length)
    return (1.0 - mix) * near * (ff + beta * ff ** 2) + mix * uu + gamma * ss


def _kernel(a: tuple, b: tuple, length: float, beta: float, mix: float, decay: str,
            gamma: float, scales: tuple) -> np.ndarray:
    return _combined(_products(a, b), length, beta, mix, decay, gamma, scales)


@dataclasses.dataclass
class Sensors:
    """What the patient's K FE simulations say of any load by reciprocity (Maxwell-Betti: in
    the linear range, the displacement at point a along d caused by a force f at b is f . the
    displacement at b caused by a unit force at a along d). Simulation k's first load step
    (the smallest force, nearly linear) divided by its force gives that unit field; a load
    (b, f) then reads f . it at b, the displacement it causes at simulation k's load point
    along its force, less what the population model's field for the load puts there: a
    reading of the load's residual at the K load points, known for a new load without its
    FE simulation. A load not at an output node reads the fields at the nearest one.
    """

    nodes: np.ndarray        # (n_out, 3) mm: the output nodes
    at: np.ndarray           # (K,) the output node of each simulation's load point
    along: np.ndarray        # (K, 3) its force's direction
    unit: np.ndarray         # (K, n_out, 3) mm/N: its first load step's field per newton
    sims: np.ndarray         # (K,) their simulations
    tree: object = dataclasses.field(repr=False, compare=False)  # KD-tree of the nodes

    @classmethod
    def of(cls, nodes, x, f, fields, groups) -> Sensors:
        """From the cases of the FE simulations: load points ``x`` (n, 3) mm, forces ``f``
        (n, 3) N, ``fields`` (n, n_out, 3) mm at the output ``nodes``, each case's
        simulation ``groups``.
        """
        from scipy.spatial import cKDTree

        nodes, f, groups = np.asarray(nodes, float), np.asarray(f, float), np.asarray(groups)
        sims = np.unique(groups)
        norms = np.linalg.norm(f, axis=1)
        first = np.array([np.flatnonzero(groups == s)[np.argmin(norms[groups == s])]
                          for s in sims])
        tree = cKDTree(nodes)
        at = tree.query(np.asarray(x, float)[first])[1]
        size = np.maximum(norms[first], 1e-30)[:, None]
        unit = np.asarray(fields, float)[first] / size[:, :, None]
        return cls(nodes, at, f[first] / size, unit, sims, tree)

    def __call__(self, x, f, fields, groups=None) -> np.ndarray:
        """(n, K) mm: the readings of loads at ``x`` (n, 3) mm with forces ``f`` (n, 3) N whose
        population fields are ``fields`` (n, m); ``groups``: the cases' own simulations, which
        read nothing of themselves (zero), as a new load has no simulation of its own.
        """
        b = self.tree.query(np.asarray(x, float).reshape(-1, 3))[1]
        f = np.asarray(f, float).reshape(-1, 3)
        said = np.einsum("knc,nc->nk", self.unit[:, b], f)
        put = np.einsum("nkc,kc->nk", np.asarray(fields, float).reshape(
            len(f), len(self.nodes), 3)[:, self.at], self.along)
        out = said - put
        if groups is not None:
            out[np.asarray(groups)[:, None] == self.sims[None, :]] = 0.0
        return out


MIXES = (0.0, 0.5, 1.0)                      # weight of the population fields' product
GAMMAS = (0.0, 0.3, 1.0, 3.0)                # weight of the reciprocity readings' product
MIN_GAIN = 0.01                              # a kept correction lowers the held-out
                                             # MEE by at least this fraction (a heavily
                                             # ridged fit of noise scrapes a few 1e-4)
CV_STEPS = 4                                 # load steps per simulation the setting is
                                             # chosen on

def _take(cases: tuple, idx) -> tuple:
    return tuple(c[idx] for c in cases)


@dataclasses.dataclass
class Correction:
    """Kernel ridge regression of residual fields on the load (one load per case), the
    population model's field for it and its reciprocity readings.
    """

    cases: tuple            # the training cases: load points, forces, population fields,
    #                         readings
    weights: np.ndarray     # (n, m): dual coefficients, m = output nodes x 3
    setting: tuple          # (length mm, beta, mix, decay, gamma, ridge)
    scales: tuple           # the force's scale (N), the fields' and the readings' (mm)
    sensors: Sensors | None = None   # what gives a load its readings (None: no readings)
    cv_mee: float = float("nan")   # mm: the chosen setting's cross-validated residual MEE

    def __call__(self, points, forces, fields) -> np.ndarray:
        """(cases, m) residual at load points (cases, 3) mm with forces (cases, 3) N and the
        population model's fields (cases, m) mm for them.
        """
        b = _cases(points, forces, fields, self.sensors)
        return _kernel(b, self.cases, *self.setting[:-1], self.scales) @ self.weights


def _cases(x, f, u, sensors: Sensors | None, groups=None) -> tuple:
    """The kernel's cases: load points, forces, population fields, reciprocity readings
    (none without ``sensors``), each (n, ...) float64.
    """
    x, f, u = (np.asarray(a, dtype=np.float64).reshape(len(a), -1) for a in (x, f, u))
    s = np.zeros((len(x), 0)) if sensors is None else sensors(x, f, u, groups)
    return x, f, u, s



def _sq(pred, true) -> float:
    return float(np.mean(np.sum((pred - true) ** 2, axis=1)))


def _cv_scores(cases: tuple, r, groups, scales: tuple, score=_sq, grid=None,
               columns=None) -> dict:
    """{(length, beta, mix, decay, gamma, ridge): mean held-out ``score``} over folds of
    whole simulations; ``grid``: the (length, beta, mix, decay, gamma) tried (default: every
    one, gamma 0 only without readings) with every ridge; ``columns``: the simulation each
    reading comes from (a fold's held-out simulations read nothing).
    """
    folds = simulation_folds(groups, 5)
    gammas = GAMMAS if cases[3].shape[1] else (0.0,)
    grid = grid or [(ln, b, m, d, g) for ln in LENGTHS for b in BETAS for m in MIXES
                    for d in DECAYS for g in gammas]
    products = _products(cases, cases)  # once: every fold's kernels are slices of it
    scores: dict = {}
    for held in folds:
        te = np.isin(groups, held)
        if cases[3].shape[1]:
            s = cases[3][:, ~np.isin(columns, held)]
            products = (*products[:3], s @ s.T)
        for kernel in grid:
            full = _combined(products, *kernel, scales)
            k = full[np.ix_(~te, ~te)]
            lam, q = np.linalg.eigh(k)
            qr = q.T @ r[~te]
            kt = full[np.ix_(te, ~te)] @ q
            diag = max(float(np.mean(np.diag(k))), 1e-30)
            for ridge in RIDGES:
                pred = kt @ (qr / (np.maximum(lam, 0.0) + ridge * diag)[:, None])
                key = (*kernel, ridge)
                scores[key] = scores.get(key, 0.0) + score(pred, r[te]) / len(folds)
    return scores


def spread_steps(groups: np.ndarray) -> np.ndarray:
    """The cases the cross-validation uses: at most CV_STEPS of each simulation's, spread
    over its steps and ending at its last.
    """
    out = []
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        out.append(idx[np.unique(np.linspace(idx.size - 1, 0, CV_STEPS).round().astype(int))])
    return np.sort(np.concatenate(out))


def fit_correction(x, f, u, r, groups, sensors: Sensors | None = None) -> Correction | None:
    """The correction of residuals ``r`` (n, m) for loads at ``x`` (n, 3) mm with forces ``f``
    (n, 3) N whose population fields are ``u`` (n, m); ``groups``: each case's simulation (the
    cross-validation holds out whole ones); ``sensors``: the loads' reciprocity readings
    (:class:`Sensors` of these simulations; None: none). The setting is the one of least
    cross-validated squared error, computed on at most CV_STEPS load steps of each simulation
    (the steps of one load are nearly proportional) and on the residuals' singular
    coordinates (the same sums, far fewer columns). None (no correction) with fewer than two
    simulations, or when the nested cross-validated MEE of the whole fit (:func:`_nested_mee`)
    is not MIN_GAIN below the residual's own.
    """
    groups = np.asarray(groups)
    if np.unique(groups).size < 2:
        return None   # nothing to check a setting on
    cases = _cases(x, f, u, sensors, groups)
    r = np.asarray(r, dtype=np.float64)
    scales = tuple(float(np.linalg.norm(c, axis=1).max(initial=0.0)) or 1.0
                   for c in cases[1:])
    columns = None if sensors is None else sensors.sims
    sub = spread_steps(groups)
    cs, rs, gs = _take(cases, sub), r[sub], groups[sub]
    cv = _nested_mee(cs, rs, gs, scales, columns)
    if cv >= (1.0 - MIN_GAIN) * mee(rs):   # no better than the base on held-out
        #                                     simulations
        return None
    setting = _selected(cs, rs, gs, scales, columns)
    return Correction(cases, _weights(cases, r, setting, scales), setting, scales, sensors, cv)


def _selected(cs: tuple, rs, gs, scales: tuple, columns) -> tuple:
    """The setting of least cross-validated squared error (on the residuals' singular
    coordinates: the same sums, far fewer columns).
    """
    left, sv, _ = np.linalg.svd(rs, full_matrices=False)
    scores = _cv_scores(cs, left * sv, gs, scales, columns=columns)
    return min(scores, key=scores.get)


def _weights(cases: tuple, r, setting: tuple, scales: tuple) -> np.ndarray:
    k = _kernel(cases, cases, *setting[:-1], scales)
    diag = max(float(np.mean(np.diag(k))), 1e-30)
    return np.linalg.solve(k + setting[-1] * diag * np.eye(k.shape[0]), r)


def _nested_mee(cs: tuple, rs, gs, scales: tuple, columns) -> float:
    """The cross-validated MEE of the whole fit, its choice of setting included: each
    fold's simulations predicted by a correction whose setting was selected (and fitted) on
    the other simulations alone, reading none of the fold's. Scoring the setting chosen on
    all folds on those same folds instead is biased low (the least of 1,680 noisy scores):
    it kept corrections that made held-out simulations worse. Infinite when a fold leaves
    fewer than two simulations to select on.
    """
    folds = simulation_folds(gs, 5)
    total = 0.0
    for held in folds:
        te = np.isin(gs, held)
        if np.unique(gs[~te]).size < 2:
            return float("inf")
        inner, cols = cs, columns
        if columns is not None:
            keep = ~np.isin(columns, held)
            inner, cols = (*cs[:3], cs[3][:, keep]), columns[keep]
        train = _take(inner, ~te)
        setting = _selected(train, rs[~te], gs[~te], scales, cols)
        w = _weights(train, rs[~te], setting, scales)
        pred = _kernel(_take(inner, te), train, *setting[:-1], scales) @ w
        total += mee(pred, rs[te]) / len(folds)
    return total
