"""What the surrogate adds to a grasp over a liver's Green's function
(:class:`data_spec.green_grasp.GreenGrasp`, the relation itself): how a force pressed on a
patch is spread over its nodes, and the tool's force on the Ogden liver beyond the
small-strain one (:class:`GraspForce`). numpy only.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from data_spec.eligible_loads import min_distance

# mm: beyond this pull a grasp's small-strain base is off by millimetres and its force far too
# low, the Ogden liver stiffening (docs/surgical_loads.md): predict-liver and the manipulator
# say so
SMALL_PULL_MM = 5.0


def patch_weights(points: np.ndarray, triangles: np.ndarray, patch, centre: int,
                  radius: float) -> np.ndarray:
    """(len(patch),) the shares of a force pressed on a patch (summing to 1) that its nodes
    carry as nodal forces: each node's lumped surface area (a third of its triangles') times
    the bump (1 - (r / radius)^2)^2 of its distance r to ``centre``, the footprint the
    solver's PatchLoad spreads as a traction (the node at the centre alone when the patch is
    that one node).
    """
    patch = np.asarray(patch, dtype=np.int64)
    t = np.asarray(triangles, dtype=np.int64)
    x = points[t]
    area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
    lumped = np.zeros(points.shape[0])
    for k in range(3):
        np.add.at(lumped, t[:, k], area / 3.0)
    r = np.linalg.norm(points[patch] - points[int(centre)], axis=1) / radius
    w = lumped[patch] * np.clip(1.0 - r**2, 0.0, None) ** 2
    if w.sum() <= 0.0:
        raise ValueError(f"the patch around node {centre} carries no area")
    return w / w.sum()


@dataclasses.dataclass(frozen=True)
class GraspForce:
    """A tool's force on the Ogden liver from its small-strain force ``F_lin``:
    F = F_lin exp(p (a + b p + k ln(|F_lin| / p) + dist r + cos c)), p the tool's pull (mm),
    |F_lin| / p its small-strain stiffness along the pull (N/mm), r the grasp's distance to
    the fixed region (mm, its centre's to the nearest fixed node) and c = cos(F_lin, d). The
    Ogden law stiffens as it stretches, so the force of a pull of centimetres is well above
    the linear one, and how fast it stiffens depends on the grasp: a stiff grasp near the
    support stretches its tissue more for the same pull. The coefficients are fitted
    (:meth:`fit`) by least squares of log(|F_FE| / |F_lin|) over a grasp population's
    training samples, the FE reaction forces against the small-strain base's (``fem_sim
    linear --population``: each tool's force at fraction 1). In the log a factor too high and
    one too low by the same ratio weigh alike. Every term carries the pull: the law is the
    base itself in the small-strain limit, as the FE is (p -> 0). All zero: the base.
    """

    a: float = 0.0
    b: float = 0.0
    k: float = 0.0
    dist: float = 0.0
    cos: float = 0.0

    @staticmethod
    def terms(d, f_lin, dist=None) -> np.ndarray:
        """(..., 5): p, p^2, p ln(|F_lin| / p), p r, p cos(F_lin, d) of each tool's pull ``d``
        (..., 3) mm, small-strain force ``f_lin`` (..., 3) N and distance ``dist`` (...) mm
        to the fixed region (None: 0, for a law with no ``dist``); 0 where the pull is 0.
        """
        d, f_lin = np.asarray(d, np.float64), np.asarray(f_lin, np.float64)
        p, fl = np.linalg.norm(d, axis=-1), np.linalg.norm(f_lin, axis=-1)
        moved = (p > 0) & (fl > 0)
        ps, fs = np.where(moved, p, 1.0), np.where(moved, fl, 1.0)
        r = np.zeros_like(p) if dist is None else np.broadcast_to(dist, p.shape)
        c = np.sum(d * f_lin, axis=-1) / (ps * fs)
        return np.where(moved[..., None], np.stack(
            [p, p * p, p * np.log(fs / ps), p * r, p * c], axis=-1), 0.0)

    @classmethod
    def fit(cls, d, f_lin, f_fe, dist=None, use: tuple | None = None) -> GraspForce:
        """From the tools' pulls ``d`` (..., 3) mm, the base's forces and the FE's (..., 3) N
        and their distances to the fixed region ``dist`` (...) mm (None: a law without it);
        ``use``: the coefficients fitted (default: all those the inputs allow), the others 0.
        """
        x = cls.terms(d, f_lin, dist).reshape(-1, 5)
        f_lin, f_fe = (np.asarray(f, np.float64).reshape(-1, 3) for f in (f_lin, f_fe))
        ratio = np.linalg.norm(f_fe, axis=1) / np.linalg.norm(f_lin, axis=1)
        ok = (x[:, 0] > 0) & np.isfinite(ratio) & (ratio > 0)
        names = [f.name for f in dataclasses.fields(cls)]
        use = use or [n for n in names if n != "dist" or dist is not None]
        used = [names.index(n) for n in use]
        coef = np.zeros(5)
        coef[used] = np.linalg.lstsq(x[ok][:, used], np.log(ratio[ok]), rcond=None)[0]
        return cls(*map(float, coef))

    def factor(self, d, f_lin, dist=None) -> np.ndarray:
        """(...): the stiffening of each tool's small-strain force (:meth:`terms` times the
        coefficients, in fewer operations, one tool's in floats: a haptic loop calls it);
        ValueError when the law needs the tools' distance to the fixed region and it is not
        given.
        """
        if dist is None and self.dist != 0.0:
            raise ValueError("this grasp force law needs each tool's distance to the fixed "
                             "region (mm)")
        d, f = np.asarray(d, np.float64), np.asarray(f_lin, np.float64)
        r = 0.0 if dist is None else np.asarray(dist, np.float64)
        if d.size == 3:   # one tool
            (x, y, z), (u, v, w) = d.reshape(3).tolist(), f.reshape(3).tolist()
            p, fl = math.sqrt(x * x + y * y + z * z), math.sqrt(u * u + v * v + w * w)
            rr = float(np.ravel(r)[0])
            e = self._exponent(p, fl, x * u + y * v + z * w, rr) if p > 0 < fl else 0.0
            return np.full(d.shape[:-1], math.exp(e))
        # no pull (and so no small-strain force): every term 0, the factor 1
        p = np.maximum(np.sqrt(np.sum(d * d, axis=-1)), 1e-300)
        fl = np.maximum(np.sqrt(np.sum(f * f, axis=-1)), 1e-300)
        return np.exp(self._exponent(p, fl, np.sum(d * f, axis=-1), r))

    def _exponent(self, p, fl, dot, r):
        """The log of the factor from the pull's length ``p``, the small-strain force's
        ``fl``, their dot product and the distance ``r`` (floats or arrays, all > 0).
        """
        return (p * (self.a + self.b * p + self.k * np.log(fl / p) + self.dist * r)
                + self.cos * dot / fl)

    def pull_for(self, stiffness, force, dist=None) -> np.ndarray:
        """(3,) mm: the pull of one tool whose force by this law is ``force`` (3,) N, the
        tool's small-strain stiffness ``stiffness`` (3, 3) N/mm (F_lin = K d) and distance
        ``dist`` mm to the fixed region: a force held by the tool (a haptic device's
        admittance). The law scales K d, so the pull lies along K^-1 F and its length p
        solves ln p + ln factor(p) = ln |K^-1 F| (Newton in ln p); K^-1 F itself when the
        law is the base's (all zero), as in the small-strain limit. ValueError when the
        equation has no root (a law that softens faster than the pull grows).
        """
        q = np.linalg.solve(np.asarray(stiffness, np.float64), np.asarray(force, np.float64))
        size = float(np.linalg.norm(q))
        if size == 0.0:
            return q
        e = q / size
        ke = np.asarray(stiffness, np.float64) @ e
        fl = float(np.linalg.norm(ke))
        # ln factor(p e) = alpha p + b p^2, the stiffness along e and the cosine fixed
        alpha = self._exponent(1.0, fl, float(e @ ke), 0.0 if dist is None else float(dist)) \
            - self.b
        p = size
        for _ in range(100):
            slope = 1.0 + alpha * p + 2.0 * self.b * p * p   # d g / d ln p
            if slope <= 0.0:
                raise ValueError("the force law softens: no pull gives this force")
            step = -(math.log(p) + alpha * p + self.b * p * p - math.log(size)) / slope
            p *= math.exp(step)
            if abs(step) < 1e-13:
                return p * e
        raise ValueError("the pull for this force did not converge")

    def __call__(self, d, f_lin, dist=None) -> np.ndarray:
        """The tools' forces (..., 3) N for their pulls ``d`` (..., 3) mm, base forces and
        distances to the fixed region (mm).
        """
        return np.asarray(f_lin) * self.factor(d, f_lin, dist)[..., None]


def fixed_distance(points, fixed, at) -> np.ndarray:
    """(len(at),) mm: each node ``at``'s distance to the nearest of the ``fixed`` nodes."""
    x = np.asarray(points, np.float64)
    return min_distance(x[np.atleast_1d(np.asarray(at, np.int64))], x[np.asarray(fixed)])


def tool_distances(ds) -> np.ndarray:
    """(S, n_tools) mm: each grasp sample's tools' distance to its liver's fixed region."""
    out = np.empty(ds.load_points.shape[:2])
    for g in np.unique(ds.sample_geo):
        at = np.flatnonzero(ds.sample_geo == g)
        out[at] = min_distance(ds.load_points[at].reshape(-1, 3),
                               ds.points[g][ds.fixed[g]]).reshape(at.size, -1)
    return out


def grasp_over_base(placed, at, d, u_base, f_base, held=None,
                    dist=None) -> tuple[np.ndarray, np.ndarray]:
    """A model of grasps over a grasp's small-strain base: (the base's field ``u_base``
    (n, 3) mm at the nodes of ``placed`` (a :class:`~surrogate.predict_liver.PlacedModel`)
    plus the placed network's rest for the tools' pulls ``d`` (T, 3) mm at the template nodes
    ``at`` (T,), nothing added at the rows ``held`` (the grasped nodes move with their tool);
    the base's forces ``f_base`` (T, 3) N stiffened by the model's :class:`GraspForce` (the
    tools' distances ``dist`` (T,) mm to the fixed region), or as they are when it has none).
    """
    d = np.asarray(d, dtype=np.float64)
    rest = placed(d[None], np.asarray(at)[None], rest=True)[0]
    if held is not None:
        rest[np.asarray(held, dtype=np.int64)] = 0.0
    force = placed.predictor.grasp_force
    return u_base + rest, (f_base if force is None else force(d, f_base, dist))


def base_forces(ds) -> np.ndarray:
    """(S, n_tools, 3) N: each sample of the grasp dataset ``ds``, its tools' small-strain
    force at the sample's step (its small-strain files' force at fraction 1, scaled);
    ValueError when ``ds`` has no reaction forces or its files hold no tools' forces (rerun
    ``fem_sim linear --population DATA --order 1``).
    """
    from surrogate.linear_base import PopulationLinearBase

    if getattr(ds, "reactions", None) is None:
        raise ValueError(f"{ds.directory}: not a grasp dataset (no reaction forces)")
    out = np.empty(ds.reactions.shape)
    for g, (lf, _) in PopulationLinearBase(ds, order=1).files.items():
        if lf.tool_force is None:
            raise ValueError(f"{ds.directory}/linear: no tools' forces; rerun fem_sim linear "
                             f"--population {ds.directory} --order 1")
        at = np.flatnonzero(ds.sample_geo == g)
        out[at] = ds.sample_fraction[at, None, None] * lf.tool_force[lf.rows(ds.sample_sim[at])]
    return out


def force_error_pct(f, f_fe) -> np.ndarray:
    """|f - f_fe| / |f_fe| in %, per tool."""
    return 100.0 * np.linalg.norm(np.asarray(f) - f_fe, axis=-1) / np.linalg.norm(f_fe, axis=-1)


def heldout_forces(ds, folds: list, cfg: dict) -> dict:
    """Each tool's force on the held-out livers of ``folds`` (lists of held-out samples of the
    grasp dataset ``ds``; ``cfg`` the training settings), error in % of the FE reaction per
    sample and tool, with its ``pull`` (mm) and ``liver``: the small-strain ``base``, the law
    of the pull alone fitted on each fold's training samples (``pull``), the whole
    :class:`GraspForce` fitted so (``law``), and the ``floor`` any law that scales the base's
    force leaves (the FE force's component across the base's direction).
    """
    from surrogate.data import training_samples

    d, f_lin, f_fe = np.asarray(ds.forces, np.float64), base_forces(ds), ds.reactions
    r = tool_distances(ds)
    out = {k: [] for k in ("pull", "liver", "base", "law_pull", "law", "floor")}
    for held in folds:
        train = training_samples(ds, held, cfg)
        args = (d[train], f_lin[train], f_fe[train], r[train])
        laws = {"law_pull": GraspForce.fit(*args, use=("a", "b")), "law": GraspForce.fit(*args)}
        out["pull"].append(np.linalg.norm(d[held], axis=-1).ravel())
        out["liver"].append(np.repeat(ds.sample_geo[held], d.shape[1]))
        out["base"].append(force_error_pct(f_lin[held], f_fe[held]).ravel())
        for name, law in laws.items():
            out[name].append(force_error_pct(law(d[held], f_lin[held], r[held]),
                                             f_fe[held]).ravel())
        unit = f_lin[held] / np.linalg.norm(f_lin[held], axis=-1, keepdims=True)
        best = np.sum(f_fe[held] * unit, axis=-1, keepdims=True) * unit
        out["floor"].append(force_error_pct(best, f_fe[held]).ravel())
    return {k: np.concatenate(v) for k, v in out.items()}


def heldout_grasp_force(data, run, large_mm: float = 20.0) -> dict:
    """The tools' force on the held-out livers of a grasp population run's evaluated folds
    (``RUN/config.json``: its folds and seed), :func:`heldout_forces`'s ``base`` and
    ``model`` (the whole law): median and worst, over every pull and over pulls beyond
    ``large_mm``.
    """
    import json
    from pathlib import Path

    from surrogate.data import kfold_groups, load_dataset

    cfg = json.loads((Path(run) / "config.json").read_text())
    ds = load_dataset(data)
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])[:cfg.get("evaluate_folds") or None]
    got = heldout_forces(ds, folds, cfg)
    p, errors = got["pull"], {"base": got["base"], "model": got["law"]}
    return {"large_mm": large_mm, "tools": int(p.size), **{
        k: {"median_pct": float(np.median(e)), "worst_pct": float(e.max()),
            "large_median_pct": float(np.median(e[p > large_mm])) if np.any(p > large_mm)
            else float("nan")} for k, e in errors.items()}}
