"""``python -m surrogate train --data DIR --run RUN [--config NAME] [--fresh] [key=value ...]``
and ``python -m surrogate predict-liver RUN LIVER --force X Y Z FX FY FZ [--out DIR]``.

A killed training resumes when the same command is run again (``--fresh`` starts over).
"""

from __future__ import annotations

import argparse
import json
import sys


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def main(argv=None) -> int:
    from liverreg.shape_model import SHAPE_RULES

    parser = argparse.ArgumentParser(prog="python -m surrogate")
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="k-fold CV, metrics, plots and an exported model")
    t.add_argument("--data", required=True, help="dataset directory written by fem_sim")
    t.add_argument("--run", required=True, help="run directory to write")
    t.add_argument("--config", help="config name (default: the scene's surrogate.config)")
    t.add_argument("--fresh", action="store_true",
                   help="discard RUN/checkpoints instead of resuming from them")
    t.add_argument("overrides", nargs="*", metavar="key=value",
                   help="config overrides, e.g. epochs=20 hidden=[64,64]")
    p = sub.add_parser("predict-liver", help="place a liver never seen in the training "
                       "population and predict its displacement (models of scene 4)")
    p.add_argument("run", help="a run directory whose model was trained on a population")
    p.add_argument("liver", help="the liver: a surface (.vtk .vtp .stl .obj .ply) or a volume "
                   "mesh (.vtu, .vtk, data_spec .h5), in mm")
    p.add_argument("--force", nargs=6, type=float, action="append", default=[],
                   metavar=("X", "Y", "Z", "FX", "FY", "FZ"),
                   help="a force FX FY FZ (N) at the liver surface point nearest to X Y Z "
                   "(mm); once per load of the model. Without it the manipulator (a window) "
                   "opens on the placed liver")
    p.add_argument("--out", default="predict-liver", help="output directory")
    p.add_argument("--scale-to-mm", type=float, default=1.0,
                   help="multiply the file's coordinates by this (1000 for metres)")
    p.add_argument("--no-center", action="store_true",
                   help="keep the liver where the file puts it (a liver already in the "
                   "population's frame and place); by default it is mapped onto the "
                   "population's mean liver (--frame)")
    p.add_argument("--frame", choices=("LPS", "RAS", "population", "auto"), default="LPS",
                   help="the liver file's frame: LPS (DICOM, ITK; the default), RAS (NIfTI, "
                   "Slicer), population (x toward the right lobe, y posterior, z up), or auto "
                   "(the best rigid fit onto the population's mean liver, mirror images "
                   "included; it may turn a liver unlike the population's away from its "
                   "anatomy)")
    p.add_argument("--shape", choices=SHAPE_RULES,
                   help="the shape the network is told for a liver outside the population: "
                   "own (the liver's coefficients), range (clipped to the population's "
                   "ranges), radius (scaled back to the population's largest Mahalanobis "
                   "radius), hull (the nearest mix of the population's livers) or outside "
                   "(that mix also for a liver with a coefficient beyond the ranges); default: "
                   "the design's (node-wise: range, population basis: outside; "
                   "docs/shape_rule.md)")
    p.add_argument("--no-picture", action="store_true", help="no PNG (no OpenGL needed)")
    args = parser.parse_args(argv)
    if args.command == "predict-liver":
        if not args.force:  # no force given: the manipulator opens on the placed liver
            from surrogate.viewer import main as viewer

            return viewer([str(args.run), "--place", str(args.liver), "--scale-to-mm",
                           str(args.scale_to_mm), "--frame", args.frame,
                           *(["--shape", args.shape] if args.shape else [])]
                          + (["--no-center"] if args.no_center else []))
        from surrogate.predict_liver import main as predict_liver

        return predict_liver(args)

    from pathlib import Path

    from data_spec import SceneError, load_scene
    from surrogate.config import get_config
    from surrogate.data import DataError
    from surrogate.train import train_and_evaluate

    try:
        scene = load_scene(Path(args.data) / "scene.toml")
    except SceneError as exc:
        print(f"surrogate train: {exc}", file=sys.stderr)
        return 2
    bad = [kv for kv in args.overrides if "=" not in kv]
    if bad:
        print(f"surrogate train: overrides are key=value, got {bad}", file=sys.stderr)
        return 2
    overrides = dict(kv.split("=", 1) for kv in args.overrides)
    overrides = {k: _value(v) for k, v in overrides.items()}
    name = args.config or scene["surrogate"]["config"]
    overrides.setdefault("folds", scene["surrogate"]["folds"])
    overrides.setdefault("node_fraction", scene["surrogate"]["node_fraction"])
    try:
        cfg = get_config(name, **overrides)
    except ValueError as exc:
        print(f"surrogate train: {exc}", file=sys.stderr)
        return 2
    if cfg["design"] == "basis" and scene.varies["geometry"]:
        print(f"surrogate train: config {name!r} (design 'basis') needs a scene with one liver; "
              f"{args.data}/scene.toml varies the geometry: use a node-wise config",
              file=sys.stderr)
        return 2
    if cfg["design"] == "population_basis" and not scene.varies["geometry"]:
        print(f"surrogate train: config {name!r} (design 'population_basis') needs a "
              f"population of livers; {args.data}/scene.toml has one liver: use config "
              "'basis'", file=sys.stderr)
        return 2
    if Path(args.run).exists() and not Path(args.run).is_dir():
        print(f"surrogate train: --run {args.run} is a file, not a directory", file=sys.stderr)
        return 2
    try:
        result = train_and_evaluate(args.data, args.run, cfg, fresh=args.fresh)
    except (DataError, OSError) as exc:  # OSError: a run directory that cannot be written
        print(f"surrogate train: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({k: result[k] for k in ("scene", "skill", "training_seconds")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
