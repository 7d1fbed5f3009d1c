"""Frame rate of the manipulator (surrogate.viewer), whole liver against surface only.

    .venv-train/bin/python bench/bench_viewer.py --run runs/demo/train [--run RUN2 ...]
        [--frames 60] [--repeats 3] [--size 900 700] [--md docs/viewer.md]

For each model and each node set ("surface": the surrogate predicts the drawn surface
vertices; "all": every node of the liver, the surface drawn from it) the default pull sequence
is drawn off-screen (Mesa's software OpenGL through EGL, as in a window under Xvfb): median
inference time, median frame time (inference + moving the surface + arrows + status line +
rendering) and frames per second, median over ``--repeats`` runs. ``make bench-viewer`` also
builds the 15k-node real-liver model it measures (bench/viewer_sofa.toml).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

from liverviz.pictures import pyvista
from liverviz.report import header
from surrogate.manipulator import Manipulator
from surrogate.predictor import load_predictor
from surrogate.viewer import LiverScene, apply_frame, load_script, model_dir


def measure(run: Path, nodes: str, frames: int, repeats: int, size) -> dict:
    pv = pyvista()
    pred = load_predictor(model_dir(run))
    m = Manipulator(pred, nodes=nodes)
    script, _ = load_script(None, m)
    script = (script * (frames // len(script) + 1))[:frames]
    clim = m.colour_range()
    inference, frame = [], []
    for _ in range(repeats):
        p = pv.Plotter(off_screen=True, window_size=size)
        scene = LiverScene(p, m, clim)
        apply_frame(m, script[0])
        scene.draw()
        p.screenshot(return_img=True)  # the first real render (buffers, shaders) not counted
        inf, fr = [], []
        for f in script:
            apply_frame(m, f)
            scene.draw()
            inf.append(scene.last.seconds)
            fr.append(scene.last_frame_s)
        p.close()
        inference.append(np.median(inf))
        frame.append(np.median(fr))
    return {"run": str(run), "scene": pred.meta.get("scene", ""), "design": pred.design,
            "hidden": pred.meta["config"]["hidden"], "nodes": nodes,
            "liver_nodes": int(m.points.shape[0]), "surface_nodes": int(m.surface.nodes.size),
            "predicted_nodes": m.n_predicted, "triangles": int(m.surface.triangles.shape[0]),
            "inference_ms": float(np.median(inference) * 1e3),
            "frame_ms": float(np.median(frame) * 1e3),
            "fps": float(1e3 / (np.median(frame) * 1e3))}


def table(rows: list[dict]) -> str:
    head = ("| model | liver nodes | predicted | design, net | inference ms | frame ms | fps |\n"
            "|---|---:|---|---|---:|---:|---:|")
    lines = [head]
    for r in rows:
        net = f"{r['design']}, {'x'.join(map(str, r['hidden']))}"
        lines.append(f"| {r['scene']} | {r['liver_nodes']:,} | {r['nodes']} "
                     f"({r['predicted_nodes']:,}) | {net} | {r['inference_ms']:.2f} | "
                     f"{r['frame_ms']:.1f} | {r['fps']:.0f} |")
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", type=Path, action="append", required=True)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--size", type=int, nargs=2, default=(900, 700))
    ap.add_argument("--md", type=Path, help="write the table and the set-up here")
    args = ap.parse_args()
    rows = []
    for run in args.run:
        for nodes in ("surface", "all"):
            r = measure(run, nodes, args.frames, args.repeats, tuple(args.size))
            rows.append(r)
            print(json.dumps(r), flush=True)
    text = table(rows)
    print(text)
    if args.md:
        args.md.write_text(
            header("Manipulator frame rate (make bench-viewer)") +
            f"{platform.processor() or platform.machine()}, 2 cores, no GPU: Mesa's software "
            "OpenGL (llvmpipe) through EGL, off-screen, window "
            f"{args.size[0]} x {args.size[1]}; the default pull sequence, {args.frames} "
            f"frames, median over {args.repeats} runs. A frame is the surrogate's inference, "
            "moving the surface, redrawing the force arrow and the status line, and "
            "rendering. `predicted`: the nodes the surrogate computes (surface: the drawn "
            "vertices only; all: every node of the liver, as a simulator needs). The models "
            "measure speed, not accuracy: make bench-viewer trains its real-liver ones on 12 "
            "simulations for a few epochs (a frame costs the same for a well-trained network "
            "of the same size).\n\n"
            + text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
