"""What the surrogate adds to a grasp over a liver's Green's function
(:class:`data_spec.green_grasp.GreenGrasp`, the relation itself): how a force pressed on a
patch is spread over its nodes, and the tool's force on the Ogden liver beyond the
small-strain one (:class:`GraspForce`). numpy only.
"""

from __future__ import annotations

import dataclasses

import numpy as np

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
    """A tool's force on the Ogden liver from its small-strain force: F = F_lin exp(a p +
    b p^2), p the tool's pull (mm). The Ogden law stiffens as it stretches, so the force of a
    pull of centimetres is well above the linear one; (a, b) are fitted (:meth:`fit`) by least
    squares of log(|F_FE| / |F_lin|) over a grasp population's training samples, the FE
    reaction forces against the small-strain base's (``fem_sim linear --population``: each
    tool's force at fraction 1). In the log a factor too high and one too low by the same
    ratio weigh alike: a fit of the relative error favours forces too low where the ratio
    varies between grasps (from 2 to 8 at 40 mm on the real livers). (0, 0) is the base
    itself, exact in the small-strain limit, as this is at p -> 0.
    """

    a: float = 0.0
    b: float = 0.0

    @classmethod
    def fit(cls, d, f_lin, f_fe) -> GraspForce:
        """From the tools' pulls ``d`` (..., 3) mm, the base's forces and the FE's (..., 3) N."""
        p = np.linalg.norm(np.asarray(d, np.float64).reshape(-1, 3), axis=1)
        f_lin, f_fe = (np.asarray(f, np.float64).reshape(-1, 3) for f in (f_lin, f_fe))
        ratio = np.linalg.norm(f_fe, axis=1) / np.linalg.norm(f_lin, axis=1)
        ok = (p > 0) & np.isfinite(ratio) & (ratio > 0)
        (a, b), *_ = np.linalg.lstsq(np.stack([p[ok], p[ok] ** 2], axis=1), np.log(ratio[ok]),
                                     rcond=None)
        return cls(float(a), float(b))

    def factor(self, p) -> np.ndarray:
        """The stiffening exp(a p + b p^2) at pulls ``p`` mm."""
        p = np.asarray(p, dtype=np.float64)
        return np.exp(self.a * p + self.b * p * p)

    def __call__(self, d, f_lin) -> np.ndarray:
        """The tools' forces (..., 3) N for their pulls ``d`` (..., 3) mm and base forces."""
        return np.asarray(f_lin) * self.factor(
            np.linalg.norm(np.asarray(d, np.float64), axis=-1, keepdims=True))


def grasp_over_base(placed, at, d, u_base, f_base, held=None) -> tuple[np.ndarray, np.ndarray]:
    """A model of grasps over a grasp's small-strain base: (the base's field ``u_base``
    (n, 3) mm at the nodes of ``placed`` (a :class:`~surrogate.predict_liver.PlacedModel`)
    plus the placed network's rest for the tools' pulls ``d`` (T, 3) mm at the template nodes
    ``at`` (T,), nothing added at the rows ``held`` (the grasped nodes move with their tool);
    the base's forces ``f_base`` (T, 3) N stiffened by the model's :class:`GraspForce`, or
    as they are when it has none).
    """
    d = np.asarray(d, dtype=np.float64)
    rest = placed(d[None], np.asarray(at)[None], rest=True)[0]
    if held is not None:
        rest[np.asarray(held, dtype=np.int64)] = 0.0
    force = placed.predictor.grasp_force
    return u_base + rest, (f_base if force is None else force(d, f_base))


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


def heldout_grasp_force(data, run, large_mm: float = 20.0) -> dict:
    """The tools' force on the held-out livers of a grasp population run's evaluated folds
    (``RUN/config.json``: its folds and seed): :class:`GraspForce` fitted on each fold's
    training samples against the small-strain base's force, the error in % of the FE
    reaction per tool and load step (median and worst), over every pull and over pulls
    beyond ``large_mm``.
    """
    import json
    from pathlib import Path

    from surrogate.data import kfold_groups, load_dataset, training_samples

    cfg = json.loads((Path(run) / "config.json").read_text())
    ds = load_dataset(data)
    folds = kfold_groups(ds, cfg["folds"], cfg["seed"])[:cfg.get("evaluate_folds") or None]
    d, f_lin, f_fe = np.asarray(ds.forces, np.float64), base_forces(ds), ds.reactions
    pulls, base, model = [], [], []
    for held in folds:
        train = training_samples(ds, held, cfg)
        fit = GraspForce.fit(d[train], f_lin[train], f_fe[train])
        pulls.append(np.linalg.norm(d[held], axis=-1).ravel())
        base.append(force_error_pct(f_lin[held], f_fe[held]).ravel())
        model.append(force_error_pct(fit(d[held], f_lin[held]), f_fe[held]).ravel())
    p, errors = np.concatenate(pulls), {"base": np.concatenate(base),
                                        "model": np.concatenate(model)}
    return {"large_mm": large_mm, "tools": int(p.size), **{
        k: {"median_pct": float(np.median(e)), "worst_pct": float(e.max()),
            "large_median_pct": float(np.median(e[p > large_mm])) if np.any(p > large_mm)
            else float("nan")} for k, e in errors.items()}}
