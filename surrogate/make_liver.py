"""``make liver``: a liver file to a prediction in seconds.

One trainer process drives one solver process (``python -m fem_sim serve``) so that each
side starts once and works while the other does::

    python -m surrogate.make_liver MODEL LIVER --scene SCENE --dir DIR --solver PYTHON
        (--grasp "X Y Z DX DY DZ ..." | --force "X Y Z FX FY FZ ...") [--frame F]

The steps are the commands a user could type: the solver meshes the liver
(``fem_sim mesh``) while this process imports the model; ``truth-scene`` registers the
model on the mesh and writes the liver's scene while the solver imports its own modules;
the solver builds the liver's problem meanwhile (``fem_sim serve``'s ``prepare``), then
computes the Green's function at the nodes each load needs (``fem_sim linear --green
--green-near``: a grasp's patch, a force's node; the same rows as the whole surface's);
``predict-liver`` answers on the liver's own mesh. Each step's start is printed
(``make liver: <step>``, what :func:`timed_steps` times) and a failing step stops the rest
with its command's own message and exit code.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

from data_spec.scene import GRASP_RADIUS
from surrogate.solver_process import SolverProcess

STEPS = {"mesh": "make liver: meshing", "place": "make liver: placing",
         "green": "make liver: the Green's function", "predict": "make liver: predicting"}


def timed_steps(cmd: list[str], steps: dict[str, str], cwd=None) -> dict:
    """Run ``cmd`` (``make liver``, whose steps print their start: :data:`STEPS`) and time
    it as its user waits: wall seconds in all and per step, a step running from the first
    output line holding its ``steps`` text to the next step's (``checks``: before the first);
    ``ok`` and the output's last lines (``why``) when it failed.
    """
    t0, marks, out = time.perf_counter(), {"checks": 0.0}, []
    with subprocess.Popen(cmd, cwd=cwd, text=True, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT) as proc:
        for line in proc.stdout:
            marks.update({k: time.perf_counter() - t0 for k, v in steps.items()
                          if v in line and k not in marks})
            out.append(line)
    t = [*marks.values(), time.perf_counter() - t0]
    why = "" if proc.returncode == 0 else "".join(out[-3:])[-300:]
    return {"ok": proc.returncode == 0, "why": why, "seconds": t[-1],
            "steps": {k: t[i + 1] - t[i] for i, k in enumerate(marks)}}


def load_points(words: list[float]) -> list[float]:
    """Each load's point (X Y Z) of a GRASP or AT list, six numbers a load."""
    if not words or len(words) % 6:
        raise ValueError(f"expected X Y Z and three more numbers per load, got {len(words)} "
                         "numbers")
    return [v for i in range(0, len(words), 6) for v in words[i:i + 3]]


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m surrogate.make_liver", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("model", help="a population model's run (or its model directory)")
    p.add_argument("liver", help="the liver's surface or mesh file")
    p.add_argument("--scene", required=True, help="the population's scene (its mesh size, "
                   "fixed region rule and material)")
    p.add_argument("--dir", required=True, type=Path, help="where the steps write")
    p.add_argument("--solver", required=True, help="the solver environment's python")
    load = p.add_mutually_exclusive_group(required=True)
    load.add_argument("--grasp", help="\"X Y Z DX DY DZ ...\": tools moving patches (mm)")
    load.add_argument("--force", help="\"X Y Z FX FY FZ ...\": nodal forces (mm, N)")
    p.add_argument("--frame", help="the liver file's frame (predict-liver's --frame)")
    return p


def _steps(a, d: Path) -> list[tuple[str, str, list[str]]]:
    """(step, where it runs, its command's words) in order."""
    words = (a.grasp or a.force).replace(",", " ").split()
    near = " ".join(map(repr, load_points([float(w) for w in words])))
    frame = ["--frame", a.frame] if a.frame else []
    return [
        ("mesh", "solver", ["mesh", a.liver, "--scene", a.scene, "--out", d / "mesh.h5",
                            "--no-picture"]),
        ("place", "trainer", ["truth-scene", a.model, a.liver, "--scene", a.scene, "--sims",
                              "1", *frame, "--out", d / "scene.toml", "--placement",
                              d / "placement.npz", "--mesh", d / "mesh.h5"]),
        # a grasp's patch around the free node nearest its point; a force's node alone
        ("green", "solver", ["linear", d / "scene.toml", "--out", d / "data", "--green",
                             "--green-near", near, "--green-radius",
                             str(GRASP_RADIUS if a.grasp else 0.0)]),
        ("predict", "trainer", ["predict-liver", a.model, a.liver, "--base", d / "data",
                                "--placement", d / "placement.npz", *frame,
                                "--grasp" if a.grasp else "--force", *words,
                                "--out", d / "prediction"])]


# where JAX keeps compiled calls: the warm-up and predict-liver load the model as two objects,
# and the second compile of the same call is then a lookup
JAX_CACHE = Path(__file__).resolve().parents[1] / "runs" / "jax-cache"


def _compilation_cache() -> None:
    """JAX's persistent compilation cache in :data:`JAX_CACHE`, every compiled call kept."""
    import jax

    jax.config.update("jax_compilation_cache_dir", str(JAX_CACHE))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)


def _warm() -> None:
    """Import what placing and predicting need (JAX, the registration, the pictures), and
    keep JAX's compiled calls (:func:`_compilation_cache`).
    """
    _compilation_cache()
    import surrogate.evaluate  # noqa: F401
    import surrogate.over_green  # noqa: F401
    import surrogate.predict_liver  # noqa: F401
    from liverviz.pictures import pyvista

    pv = pyvista()
    pv.Plotter, pv.PolyData, pv.UnstructuredGrid   # noqa: B018 (pyvista imports these lazily)


def _warm_answer(a, d: Path) -> None:
    """While the solver computes the Green's function: the first picture's GL context opened
    (most of a process's first render) and the network compiled for this liver's placement
    and mesh, the shapes predict-liver calls it with (the persistent compilation cache,
    :data:`JAX_CACHE`, hands the compiled call to predict-liver's own predictor).
    """
    import numpy as np

    from data_spec.geometry import read_geometry
    from liverviz.pictures import pyvista
    from surrogate.evaluate import place
    from surrogate.predict_liver import PlacedModel
    from surrogate.predictor import load_predictor, model_load

    pv = pyvista()
    plotter = pv.Plotter(off_screen=True, window_size=(64, 64))
    plotter.add_mesh(pv.Sphere())
    plotter.screenshot(None, return_img=True)
    plotter.close()
    model = Path(a.model) / "model"   # as predict-liver reads it
    pred = load_predictor(model, load=model_load(model) if a.grasp else "nodal")
    placement, _ = place(pred, a.liver, a.frame, d / "placement.npz")
    points = read_geometry(d / "mesh.h5").points
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        placed = PlacedModel(pred, nodes=points, placement=placement)
        at = placed.load_nodes(points[:pred.spec.n_loads])
        placed(np.zeros((1, pred.spec.n_loads, 3)), at[None], rest=True)


def _on_solver(solver, name: str, words: list, a) -> int:
    """A solver step (``name``'s command ``words``) and this process's work meanwhile: its
    exit code. After meshing the solver builds the liver's problem while the model is
    placed; after the Green's function it ends.
    """
    solver.send(words)
    if name == "mesh":   # the trainer's modules load while the solver meshes
        _warm()
    elif name == "green":
        try:
            _warm_answer(a, a.dir)
        except Exception:  # noqa: BLE001 (a warm-up; predict-liver says what fails)
            pass
        solver.answer()   # prepare's: when it failed, linear builds the problem itself
    rc = solver.answer()
    if name == "mesh" and not rc:
        solver.send(["prepare", a.dir / "mesh.h5", a.scene])
    elif name == "green":
        solver.end()
    return rc


def main(argv=None) -> int:
    a = _parser().parse_args(argv)
    try:
        steps = _steps(a, a.dir)
    except ValueError as exc:
        print(f"make liver: {'GRASP' if a.grasp else 'AT'}: {exc}", file=sys.stderr)
        return 2
    a.dir.mkdir(parents=True, exist_ok=True)
    t0, seconds = time.perf_counter(), {}
    try:
        solver = SolverProcess(a.solver)
    except OSError as exc:
        print(f"make liver: --solver {a.solver}: cannot start it ({exc})", file=sys.stderr)
        return 2
    try:
        for name, where, words in steps:
            print(STEPS[name], flush=True)
            t = time.perf_counter()
            if where == "solver":
                rc = _on_solver(solver, name, words, a)
            else:
                from surrogate.__main__ import main as trainer

                rc = trainer([str(w) for w in words])
            seconds[name] = time.perf_counter() - t
            if rc:
                print(f"make liver: {name} failed (exit code {rc})", file=sys.stderr)
                return rc
    except OSError as exc:
        print(f"make liver: {exc}", file=sys.stderr)
        return 2
    finally:
        solver.close()
    print(f"make liver: {time.perf_counter() - t0:.1f} s from the file to {a.dir / 'prediction'} "
          f"({', '.join(f'{k} {v:.1f} s' for k, v in seconds.items())})", flush=True)
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # every file is written and closed and the solver process has ended: the interpreter's
    # teardown (JAX's and VTK's, most of a second) is skipped, nobody waits for it
    os._exit(code)
