"""The liver manipulator (pyvista): pick a point on the liver, pull, watch the surrogate deform it.

    python -m surrogate.viewer RUN_DIR                       a window (needs a display; Xvfb works)
    python -m surrogate.viewer RUN_DIR --offscreen --out DIR [--script forces.json]
                                                             frames + GIF, no display needed
    python -m surrogate.viewer RUN_DIR --compare --data DATA [--sim N] [--offscreen --out DIR]
                                                             FE beside surrogate, error coloured
    python -m surrogate.viewer LIVER_DATA --grasp [--offscreen --out DIR]
                                                             a grasping tool (make liver's data)
    python -m surrogate.viewer RUN --place LIVER --base LIVER_DATA [--grasp]
                                                             RUN over the liver's Green's function

RUN_DIR is a training run (its ``model/``) or a model directory. In the window: right-click a
surface point to move the active force there; drag the red sphere to set the force (its
magnitude is clamped to the training range and shown on screen); the slider sets the magnitude;
keys 1 / 2 choose the force of a two-force model, ``z`` sets the forces to zero, ``g`` shows
the undeformed outline, ``m`` switches the spheres between pulling (the surface follows the
sphere) and pushing (the sphere stands outside, where the push comes from). Sliders set the
material / shape inputs when the model has them. The status line shows the surrogate's
inference time and the frame time (inference + drawing). With ``--grasp`` a click grasps the
10 mm patch there and the sphere is the tool: the patch follows it (at most 40 mm), the
slider sets the pull and the status shows the tool's force, an arrow draws it
(surrogate.manipulator.GraspManipulator); a script's "forces" are then pulls in mm. With
``--base LIVER_DATA --place LIVER`` RUN, a model over the small-strain base (make liver's
MODEL), is placed on that liver and works over its own Green's function: forces as make liver
answers them on the liver's own mesh (surrogate.manipulator.GreenManipulator), or with
``--grasp`` a model of grasps adds its network's rest and stiffens the tool's force.

A script (``--script``) is JSON: ``{"fps": 10, "frames": [{"nodes": [id] or "points": [[x, y,
z]], "forces": [[fx, fy, fz]], "steps": 12, "inputs": [...]}, ...]}``; each entry is reached
from the previous one in ``steps`` frames (forces interpolated linearly), ``inputs`` sets the
material / shape values. Without a script a default pull sequence is drawn.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from liverreg.shape_model import SHAPE_RULES
from liverviz.pictures import (
    FORCE,
    LiverView,
    Panel,
    draw_panels,
    frame_camera,
    pyvista,
    render_panels,
    write_gif,
)

log_prefix = "surrogate.viewer"


class ViewerError(ValueError):
    """Bad input to the viewer; the message names the file and the key."""


def model_dir(run: Path) -> Path:
    """The model directory of a run (RUN/model) or the directory itself."""
    for d in (run / "model", run):
        if (d / "model.json").exists():
            return d
    raise ViewerError(f"{run}: no model.json in it or in {run / 'model'} (train first: "
                      "python -m surrogate train --data DATA --run RUN)")


def dataset_liver(data: Path, liver: str | None):
    """(points, fixed, triangles, shape coefficients) of a liver of a dataset (the first, or
    geometry id ``liver``): what a model trained on several livers is shown on.
    """
    from data_spec import geometry_path, list_shards, read_geometry, read_shard

    shards = list_shards(data)
    if not shards:
        raise ViewerError(f"{data}: no shards (expected {data}/sims/sim_*.h5)")
    for p in shards:
        s = read_shard(p)
        if liver is None or s.geometry_id == liver:
            g = read_geometry(geometry_path(data, s.geometry_id))
            shape = g.shape_coefficients if g.shape_coefficients is not None else np.zeros(0)
            return g.points, s.fixed_nodes, g.surface_triangles, shape
    raise ViewerError(f"{data}: no simulation on liver {liver!r}")


def _default_script(m) -> list[dict]:
    """At the far node: push in, sweep sideways, pull out, let go."""
    L = len(m.handles)
    node = m.handles[0].node
    n = m.surface.normals()[m.surface.local([node])[0]]
    side = np.cross(n, [0.0, 0.0, 1.0])
    side = side / max(np.linalg.norm(side), 1e-12)
    f = m.magnitude_max
    keys = [(np.zeros(3), 1), (-f * n, 12), (f * side, 12), (f * n * 0.6, 12),
            (-f * side, 12), (np.zeros(3), 10)]
    frames, prev = [], np.zeros((L, 3))
    for target, steps in keys:
        tgt = np.zeros((L, 3))
        tgt[0] = target
        if L > 1:
            tgt[1] = -target[[1, 2, 0]] * 0.5
        frames += _ramp(prev, tgt, steps, [h.node for h in m.handles], None)
        prev = tgt
    return frames


def _read_script(path: Path) -> tuple[list, float]:
    """(the script's frame entries, fps), the file's shape checked."""
    try:
        spec = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ViewerError(f"{path}: no such script file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ViewerError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(spec, dict) or not isinstance(spec.get("frames"), list) or \
            not spec["frames"]:
        raise ViewerError(f"{path}: expected an object with a non-empty list 'frames'")
    unknown = set(spec) - {"fps", "frames"}
    if unknown:
        raise ViewerError(f"{path}: unknown key(s) {sorted(unknown)} (expected fps, frames)")
    fps = spec.get("fps", 10)
    if not isinstance(fps, (int, float)) or not 0 < fps <= 60:
        raise ViewerError(f"{path}: fps: expected a number in (0, 60], got {fps!r}")
    return spec["frames"], float(fps)


def _array(value, shape) -> np.ndarray | None:
    """``value`` as a finite float array of ``shape``, else None."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return a if a.shape == shape and np.all(np.isfinite(a)) else None


def _frame_nodes(where: str, entry: dict, m, L: int) -> list | None:
    """The nodes a script entry moves the forces to (None: where they were)."""
    if "nodes" in entry and "points" in entry:
        raise ViewerError(f"{where}: give nodes or points, not both")
    if "nodes" in entry:
        ids = entry["nodes"]
        if not (isinstance(ids, list) and len(ids) == L and all(
                isinstance(i, int) and 0 <= i < m.points.shape[0] for i in ids)):
            raise ViewerError(f"{where}: nodes: expected {L} node id(s) in "
                              f"[0, {m.points.shape[0]}), got {ids!r}")
        fixed = sorted(set(ids) & set(m.fixed.tolist()))
        if fixed:
            raise ViewerError(f"{where}: nodes: {fixed} are in the fixed region (zero "
                              "displacement): a force there moves nothing")
        return list(ids)
    if "points" in entry:
        pts = _array(entry["points"], (L, 3))
        if pts is None:
            raise ViewerError(f"{where}: points: expected {L} finite [x, y, z] in mm")
        return [m.nearest_surface_node(p) for p in pts]
    return None


def _frame_inputs(where: str, entry: dict, m) -> list | None:
    """The material/shape inputs a script entry sets (None: as they were)."""
    if "inputs" not in entry:
        return None
    vals = entry["inputs"]
    if not (isinstance(vals, list) and len(vals) == len(m.inputs) and all(
            isinstance(v, (int, float)) and np.isfinite(v) for v in vals)):
        names = [i.name for i in m.inputs]
        raise ViewerError(f"{where}: inputs: expected {len(names)} numbers "
                          f"({', '.join(names) or 'this model takes none'})")
    return list(vals)


def load_script(path: Path | None, m) -> tuple[list[dict], float]:
    """(frames, fps) of a force script: each frame gives nodes, forces (n_loads, 3) and inputs,
    checked against the model; errors name the file and the key. None: the default script.
    """
    if path is None:
        return _default_script(m), 12.0
    entries, fps = _read_script(path)
    L = len(m.handles)
    frames, prev = [], np.zeros((L, 3))
    nodes, inputs = [h.node for h in m.handles], None
    for k, entry in enumerate(entries):
        where = f"{path}: frames[{k}]"
        if not isinstance(entry, dict):
            raise ViewerError(f"{where}: expected an object")
        bad = set(entry) - {"nodes", "points", "forces", "steps", "inputs"}
        if bad:
            raise ViewerError(f"{where}: unknown key(s) {sorted(bad)} (expected nodes or "
                              "points, forces, steps, inputs)")
        forces = _array(entry.get("forces"), (L, 3))
        if forces is None:
            raise ViewerError(f"{where}: forces: expected {L} finite [fx, fy, fz] in N, got "
                              f"{entry.get('forces')!r}")
        nodes = _frame_nodes(where, entry, m, L) or nodes
        given = _frame_inputs(where, entry, m)
        inputs = inputs if given is None else given
        steps = entry.get("steps", 1)
        if not isinstance(steps, int) or steps < 1:
            raise ViewerError(f"{where}: steps: expected an integer >= 1, got {steps!r}")
        frames += _ramp(prev, forces, steps, nodes, inputs)
        prev = forces
    return frames, fps


def _ramp(start, end, steps: int, nodes, inputs) -> list[dict]:
    """The frames that take the forces from ``start`` to ``end`` linearly in ``steps``."""
    return [{"nodes": nodes, "forces": start + (end - start) * s / steps, "inputs": inputs}
            for s in range(1, steps + 1)]


def apply_frame(m, frame: dict) -> None:
    for j, h in enumerate(m.handles):
        h.node = int(frame["nodes"][j])
        m.set_force(frame["forces"][j], j)
    if frame.get("inputs") is not None:
        for i, v in enumerate(frame["inputs"]):
            m.set_input(i, v)


def status_text(m, inference_s: float, frame_s: float | None, spheres: bool = False) -> str:
    parts = [m.describe(j) for j in range(len(m.handles))]
    for inp in m.inputs[:4]:
        parts.append(f"{inp.name} = {inp.value:.4g}")
    lines = parts + ([f"spheres {m.mode} (key m)"] if spheres else [])
    lines.append(f"inference {inference_s * 1e3:.2f} ms ({m.n_predicted} nodes, "
                 f"{m.nodes_mode})")
    if frame_s:
        lines.append(f"frame {frame_s * 1e3:.1f} ms ({1 / frame_s:.0f} fps)")
    return "\n".join(lines)


class LiverScene:
    """A plotter showing one manipulator: the liver, its arrows, its handles, the status."""

    def __init__(self, plotter, m, clim: float, spheres: bool = False):
        self.p, self.m, self.spheres = plotter, m, spheres
        plotter.set_background("white")
        # Measured with Mesa's software OpenGL at 1000 x 760: multi-sample anti-aliasing took
        # 37 of 61 ms per frame, and a corner annotation replaced per frame 90-220 ms; a text
        # actor whose string changes costs ~1 ms.
        plotter.disable_anti_aliasing()
        self.view = LiverView(plotter, m.surface, clim=(0.0, clim), f_ref=m.f_max)
        # The translucent undeformed outline took 25 of 46 ms per frame at 15k nodes: off in
        # live views (key g shows it), on in still pictures.
        self.view.ghost_actor.SetVisibility(False)
        # room for the largest displacement the colours show (a grasp's pull: 40 mm)
        frame_camera(plotter, m.surface, [h.node for h in m.handles], zoom=1.3, margin=clim)
        h = plotter.window_size[1]
        self.status = plotter.add_text(" ", position=(10, h - 34), font_size=10, color="black")
        self.status.prop.SetVerticalJustificationToTop()  # more lines grow downward
        self.last_frame_s = None
        self.last = None

    def draw(self) -> None:
        """Predict, move the surface, redraw the arrows and the status line; render."""
        t = time.perf_counter()
        frame = self.m.predict()
        self.last = frame
        self.view.update(frame.surface_u, [h.force for h in self.m.handles],
                         [h.node for h in self.m.handles])
        self.status.input = status_text(self.m, frame.seconds, self.last_frame_s, self.spheres)
        self.p.render()
        self.last_frame_s = time.perf_counter() - t

    def deformed(self) -> np.ndarray:
        return self.m.surface.points + (self.last.surface_u if self.last is not None else 0.0)


class Window:
    """The interactive manipulator's window: the liver, a sphere per force, the sliders and
    the keys, each wired to the manipulator ``m``.
    """

    def __init__(self, m, clim: float, window_size):
        pv = pyvista()
        self.m, self.window_size = m, window_size
        self.p = pv.Plotter(window_size=window_size, title="liverfem manipulator")
        self.scene = LiverScene(self.p, m, clim, spheres=True)
        self.widgets = []
        self.slider = self.p.add_slider_widget(
            self.on_magnitude, (0.0, m.magnitude_max), value=0.0, title=m.magnitude_title,
            pointa=(0.64, 0.9), pointb=(0.96, 0.9),
            interaction_event="always", color="black", title_height=0.02, slider_width=0.02,
            tube_width=0.006, fmt="%.2f")
        self._add_handles()
        self.p.enable_surface_point_picking(callback=self.on_pick, show_message=False,
                                            show_point=False, left_clicking=False)
        self._add_inputs()
        self._add_keys()

    def _add_handles(self) -> None:
        r = 0.02 * self.m.surface.size
        for j in range(len(self.m.handles)):
            self.widgets.append(self.p.add_sphere_widget(
                lambda c, w, j=j: self.on_drag(c, w, j), center=self.m.handle_position(j),
                radius=r, color=FORCE if j == 0 else "darkorange", pass_widget=True,
                test_callback=False, interaction_event="always"))

    def _add_inputs(self) -> None:
        for i, inp in enumerate(self.m.inputs[:4]):  # the leading inputs: more would not fit
            def on_input(value, i=i):
                self.m.set_input(i, value)
                self.scene.draw()

            y = 0.76 - 0.13 * i  # under the force slider, right of the status lines
            self.p.add_slider_widget(on_input, (inp.lo, inp.hi), value=inp.value,
                                     title=inp.name, pointa=(0.64, y), pointb=(0.96, y),
                                     interaction_event="end", color="black",
                                     title_height=0.02, slider_width=0.02, tube_width=0.006,
                                     fmt="%.3g")

    def _add_keys(self) -> None:
        p = self.p
        p.add_key_event("1", lambda: self.choose(0))
        p.add_key_event("2", lambda: self.choose(1))
        p.add_key_event("z", self.reset)
        p.add_key_event("g", self.toggle_ghost)
        p.add_key_event("m", self.toggle_mode)
        p.add_text("right-click: move the force; drag the sphere: set it; 1, 2: which force; "
                   "z: zero; m: pull/push; g: outline", position=(10, self.window_size[1] - 24),
                   font_size=9, color="black")

    def move_widgets(self) -> None:
        for j, w in enumerate(self.widgets):
            w.SetCenter(*self.m.handle_position(j))

    def show_magnitude(self) -> None:  # the slider follows the active force, however set
        self.slider.GetRepresentation().SetValue(self.m.magnitude())

    def on_magnitude(self, value) -> None:
        self.m.set_magnitude(value)
        self.move_widgets()
        self.scene.draw()

    def on_drag(self, center, widget, j) -> None:
        self.m.active = j
        self.m.drag(center, j)
        widget.SetCenter(*self.m.handle_position(j))  # a clamped force pulls the sphere back
        self.show_magnitude()
        self.scene.draw()

    def on_pick(self, point) -> None:
        if point is None:
            return
        self.m.pick(np.asarray(point), deformed=self.scene.deformed())
        self.move_widgets()
        self.scene.draw()

    def choose(self, j) -> None:
        if j < len(self.m.handles):
            self.m.active = j
            self.show_magnitude()
            self.scene.draw()

    def reset(self) -> None:
        for j in range(len(self.m.handles)):
            self.m.set_force(np.zeros(3), j)
        self.move_widgets()
        self.show_magnitude()
        self.scene.draw()

    def toggle_ghost(self) -> None:
        ghost = self.scene.view.ghost_actor
        ghost.SetVisibility(not ghost.GetVisibility())
        self.scene.draw()

    def toggle_mode(self) -> None:
        self.m.toggle_mode()
        self.move_widgets()
        self.scene.draw()

    def first_use(self, screenshot: Path) -> None:
        """What a user does first, through the window's own callbacks: a right-click on the
        default node of the drawn liver, then a drag of its sphere 1.5 drag lengths along
        the default script's strongest pull (clamped to the training maximum); saved.
        """
        m, scene = self.m, self.scene
        self.p.show(interactive=False, auto_close=False)
        scene.draw()
        node = m.handles[0].node
        self.on_pick(scene.deformed()[m.surface.local([node])[0]])
        frames, _ = load_script(None, m)
        pull = max((f["forces"][0] for f in frames), key=np.linalg.norm)
        tip = m.points[node] + 1.5 * m.drag_length * pull / np.linalg.norm(pull)
        self.widgets[0].SetCenter(*tip)
        self.on_drag(tip, self.widgets[0], 0)
        scene.draw()  # a second frame: its status line reports the first frame's time
        screenshot.parent.mkdir(parents=True, exist_ok=True)
        self.p.screenshot(str(screenshot))
        f = m.handles[0].force
        away = np.linalg.norm(np.asarray(self.widgets[0].GetCenter()) - m.points[node])
        print(f"{log_prefix}: window opened; picked node {m.handles[0].node}, dragged: force "
              f"{np.linalg.norm(f):.4f} N (training max {m.f_max:.4f} N), slider "
              f"{self.slider.GetRepresentation().GetValue():.4f} N, sphere at {away:.2f} mm "
              f"(drag length {m.drag_length:.2f} mm); screenshot {screenshot}")
        self.p.close()


def run_window(m, clim: float, screenshot: Path | None, window_size) -> int:
    """The interactive manipulator. With ``screenshot`` it draws the first frame (the default
    script's strongest pull), saves it and closes: the check that a window opens.
    """
    w = Window(m, clim, window_size)
    if screenshot is not None:
        w.first_use(screenshot)
        return 0
    w.scene.draw()
    w.scene.last_frame_s = None  # nothing was on screen yet: not a frame time
    w.p.show()
    return 0


def run_offscreen(m, clim: float, script: Path | None, out: Path, window_size) -> dict:
    """Render a force script to PNG frames and an animated GIF; returns the timings."""
    pv = pyvista()
    frames, fps = load_script(script, m)
    out.mkdir(parents=True, exist_ok=True)
    p = pv.Plotter(off_screen=True, window_size=window_size)
    scene = LiverScene(p, m, clim)
    images, inference, frame_times = [], [], []
    for k, fr in enumerate(frames):
        apply_frame(m, fr)
        scene.draw()
        img = p.screenshot(str(out / f"frame_{k:04d}.png"), return_img=True)
        images.append(img)
        inference.append(scene.last.seconds)
        frame_times.append(scene.last_frame_s)
    p.close()
    gif = write_gif(images, out / "manipulator.gif", fps)
    timing = {"frames": len(frames), "nodes_mode": m.nodes_mode,
              "nodes_predicted": m.n_predicted,
              "inference_ms_median": float(np.median(inference) * 1e3),
              "frame_ms_median": float(np.median(frame_times) * 1e3),
              "fps_median": float(1 / np.median(frame_times)), "gif": str(gif),
              # a new patch's unit responses solved on the spot (--solver), each request
              "new_patch_ms": [t * 1e3 for t in getattr(m, "solved_seconds", [])]}
    (out / "timings.json").write_text(json.dumps(timing, indent=1))
    return timing


def _simulation(pred, data: Path, sim: int | None):
    """The shard of simulation ``sim`` (None: the first the model never trained on), said
    when the model saw it in training.
    """
    from data_spec import list_shards, read_shard, shard_path

    unseen = pred.meta.get("unseen_simulations")
    if not list_shards(data):
        raise ViewerError(f"{data}: no shards (expected {data}/sims/sim_*.h5)")
    if sim is None:  # the first simulation the model never trained on (by file name: no reads)
        found = [i for i in (unseen or []) if shard_path(data, i).exists()]
        sim = found[0] if found else read_shard(list_shards(data)[0]).sim_index
    if not shard_path(data, sim).exists():
        raise ViewerError(f"--sim {sim}: no such simulation in {data}")
    if unseen is None:
        print(f"{log_prefix}: this model does not record its unseen simulations (exported "
              f"before they were); sim {sim} may have been in its training", file=sys.stderr)
    elif sim not in unseen:
        print(f"{log_prefix}: sim {sim} was in the model's training set; unseen: "
              f"{unseen[:10]}{' ...' if len(unseen) > 10 else ''}", file=sys.stderr)
    path = shard_path(data, sim)
    s = read_shard(path)
    if s.status != "ok" or s.n_done == 0:
        raise ViewerError(f"{path}: simulation {sim} did not converge "
                          f"({s.failure_reason}): nothing to compare with")
    return s, sim, bool(unseen and sim in unseen)


def _set_case(m, pred, data: Path, s):
    """The manipulator on the simulation's liver with its loads and material at full load."""
    from surrogate.features import material_vector

    same = s.fixed_nodes.size == m.fixed.size and np.array_equal(s.fixed_nodes, m.fixed)
    if not same and pred.points is None:  # a model of many livers: show this simulation's
        from surrogate.manipulator import Manipulator

        m = Manipulator(pred, nodes=m.nodes_mode, geometry=dataset_liver(data, s.geometry_id))
    elif not same:
        raise ViewerError(f"{data}: simulation {s.sim_index} is on another liver than the "
                          "model's")
    for j in range(len(m.handles)):
        m.handles[j].node = int(s.load_nodes[j])
        m.handles[j].force = np.asarray(s.forces[j], float) * float(s.load_fractions[-1])
    if pred.spec.material_dim:
        vec = material_vector(s.material.c, s.material.m, s.material.K)
        for i in range(pred.spec.material_dim):
            m.inputs[i].value = float(vec[i])
    return m


def compare(m, pred, data: Path, sim: int | None, out: Path | None, window_size) -> Path | None:
    """The FE solution of a simulation beside the surrogate's, and the error between them."""
    s, sim, unseen = _simulation(pred, data, sim)
    m = _set_case(m, pred, data, s)
    u_fe = np.zeros((m.points.shape[0], 3))
    u_fe[s.output_nodes] = s.displacement[-1]
    fe = u_fe[m.surface.nodes]
    nn = m.predict().surface_u
    err = np.linalg.norm(nn - fe, axis=1)
    top = float(max(np.linalg.norm(fe, axis=1).max(), np.linalg.norm(nn, axis=1).max()))
    f_ref = float(np.linalg.norm(s.forces, axis=1).max())
    common = {"surface": m.surface, "forces": s.forces * s.load_fractions[-1],
              "load_nodes": s.load_nodes, "f_ref": f_ref, "clim": (0.0, top)}
    what = "unseen by the model" if unseen else "seen in training"
    panels = [Panel(u=fe, label=f"FE (fem_sim), sim {sim}\nmax displacement "
                    f"{np.linalg.norm(fe, axis=1).max():.1f} mm", **common),
              Panel(u=nn, label=f"surrogate ({what})\nmax displacement "
                    f"{np.linalg.norm(nn, axis=1).max():.1f} mm", **common),
              Panel(**{**common, "clim": None}, u=nn, scalars=err, title="error (mm)",
                    cmap="inferno", label=f"error: surrogate - FE, on the surface\nmean "
                    f"{err.mean():.2f} mm, max {err.max():.2f} mm")]
    print(f"{log_prefix}: sim {sim}: surface mean error {err.mean():.3f} mm, max "
          f"{err.max():.3f} mm, FE max |u| {np.linalg.norm(fe, axis=1).max():.2f} mm")
    if out is not None:
        return render_panels(panels, out / f"compare_sim{sim}.png",
                             title=f"{pred.meta.get('scene', '')}: FE against surrogate")
    p = pyvista().Plotter(shape=(1, 3), window_size=window_size, title="FE against surrogate")
    draw_panels(p, panels, cols=3)
    p.link_views()
    p.show()
    return None


def _over_green(args):
    """The model of RUN placed on the liver of ``--base`` (make liver's data directory with
    the liver's Green's function; the liver's file ``--place``, the placement make liver
    saved beside the directory reused) as an OverGreen: a model of grasps with --grasp, a
    model of forces without.
    """
    from surrogate.evaluate import place
    from surrogate.over_green import OverGreen
    from surrogate.predictor import load_predictor, model_load

    if args.place is None:
        raise ViewerError("--base places the model on the liver of that directory: give the "
                          "liver's file with --place (make liver's LIVER)")
    mdir = model_dir(Path(args.run))
    pred = load_predictor(mdir, load=model_load(mdir) if args.grasp else "nodal")
    patient = None
    if getattr(args, "patient", None):
        from surrogate.patient.grasps import PatientGrasp

        if not args.grasp:
            raise ViewerError("--patient corrects a model of grasps: give --grasp")
        patient = PatientGrasp.load(args.patient)
    saved = Path(args.base).parent / "placement.npz"
    placement, found = place(pred, args.place, args.frame, saved if saved.exists() else None)
    for msg in found:
        print(f"{log_prefix}: warning: {msg}", file=sys.stderr)
    return OverGreen(pred, Path(args.base), placement, solver=args.solver, patient=patient)


def build(args):
    """(manipulator, predictor) from the command line's model and liver options."""
    from surrogate.manipulator import GraspManipulator, Manipulator
    from surrogate.predictor import load_predictor

    if getattr(args, "base", None) is not None:   # over the liver's own Green's function
        from surrogate.manipulator import GreenManipulator

        over = _over_green(args)
        if args.grasp:
            return GraspManipulator(Path(args.base), over=over, solver=args.solver), None
        return GreenManipulator(over), over.placed.predictor
    if getattr(args, "grasp", False):   # a liver's data directory with its Green's function
        from data_spec.linear_fields import linear_fields_path

        if not linear_fields_path(args.run).exists():
            raise ViewerError(f"{args.run}: --grasp takes a liver's data directory with its "
                              "Green's function (make liver's runs/liver/NAME/data): no "
                              f"{linear_fields_path(args.run).name} in it")
        return GraspManipulator(Path(args.run), solver=args.solver), None
    mdir = model_dir(Path(args.run))
    pred = load_predictor(mdir)
    geometry = None
    if getattr(args, "place", None) is not None:  # a liver never seen, placed as predict-liver
        from surrogate.predict_liver import (
            place_liver,
            read_liver_surface,
            told_note,
            told_shape,
        )

        if pred.shape_model is None:
            raise ViewerError(f"{mdir}: --place needs a model trained on a population of "
                              "livers (scene 4); this one has no shape model")
        points, tris = read_liver_surface(args.place, args.scale_to_mm)
        placement, found = place_liver(pred, points, tris, center=not args.no_center,
                                       frame=args.frame)
        for msg in found:
            print(f"{log_prefix}: warning: {msg}", file=sys.stderr)
        sm = pred.shape_model
        told, rule = told_shape(pred, placement.coefficients, getattr(args, "shape", None))
        if rule != "own":
            print(f"{log_prefix}: {told_note(rule)}", file=sys.stderr)
        geometry = (placement.points, sm.fixed_nodes, sm.surface_triangles, told)
    elif pred.points is None or pred.triangles is None:
        if args.data is None:
            raise ViewerError(f"{mdir}: the model has no liver of its own (trained on several "
                              "livers, or exported before surfaces were stored): give --data "
                              "DATASET [--liver GEOMETRY_ID]")
        geometry = dataset_liver(Path(args.data), args.liver)
    return Manipulator(pred, nodes=args.nodes, geometry=geometry), pred


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="python -m surrogate.viewer", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", help="training run directory (or its model/ directory); with "
                    "--grasp a liver's data directory holding its Green's function")
    ap.add_argument("--grasp", action="store_true",
                    help="a grasping tool on the liver of RUN, a data directory of make liver "
                    "(runs/liver/NAME/data): a click grasps the 10 mm patch there, a drag "
                    "moves it to the pointer (at most 40 mm), the field and the tool's force "
                    "from the liver's Green's function (the small-strain base); with "
                    "--base, RUN's model of grasps adds its network and force")
    ap.add_argument("--solver", metavar="PYTHON", help="the solver environment's python "
                    "(.venv-solver/bin/python): the unit responses a grasp needs and make "
                    "liver's file lacks are solved when it grasps (make manipulate gives it)")
    ap.add_argument("--base", type=Path, metavar="LIVER_DATA", help="with --place (the "
                    "liver's file): RUN (a model over the small-strain base, population_green) "
                    "over that liver's own Green's function, make liver's runs/liver/NAME/data: "
                    "the whole field of the liver's own mesh, forces (or --grasp) as make "
                    "liver answers them")
    ap.add_argument("--patient", type=Path, metavar="RUN", help="with --base and --grasp: a "
                    "patient's corrections of the model of grasps (make patient LOAD=grasp's "
                    "run), --base being that patient's data")
    ap.add_argument("--nodes", choices=("surface", "all"), default="surface",
                    help="predict the surface only (default) or every node of the liver")
    ap.add_argument("--offscreen", action="store_true", help="render to files, no window")
    ap.add_argument("--script", type=Path, help="force script (JSON) for --offscreen")
    ap.add_argument("--out", type=Path, help="output directory for --offscreen")
    ap.add_argument("--compare", action="store_true",
                    help="FE beside surrogate for a simulation of --data")
    ap.add_argument("--data", type=Path, help="dataset directory (for --compare, or the "
                    "liver of a model trained on several livers)")
    ap.add_argument("--sim", type=int, help="simulation to compare (default: the first the "
                    "model never trained on)")
    ap.add_argument("--liver", help="geometry id of --data's liver to show")
    ap.add_argument("--place", type=Path, help="a liver file never seen (surface or volume "
                    "mesh, mm), placed in the model's population as predict-liver does")
    ap.add_argument("--scale-to-mm", type=float, default=1.0,
                    help="with --place: multiply the file's coordinates by this")
    ap.add_argument("--no-center", action="store_true",
                    help="with --place: keep the liver where the file puts it")
    ap.add_argument("--frame", choices=("LPS", "RAS", "population", "auto"), default=None,
                    help="with --place: the file's frame (as predict-liver; the liver is "
                    "shown in the population's frame)")
    ap.add_argument("--shape", choices=SHAPE_RULES,
                    help="with --place: the shape the network is told for a liver outside the "
                    "population (as predict-liver; default: the design's)")
    ap.add_argument("--screenshot", type=Path,
                    help="open the window, draw one pull, save this PNG and close")
    ap.add_argument("--size", type=int, nargs=2, default=(900, 700), metavar=("W", "H"))
    return ap


def main(argv=None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    if args.offscreen and args.out is None:
        ap.error("--offscreen needs --out DIR")
    if args.script is not None and not args.offscreen:
        ap.error("--script is for --offscreen (the window is driven by the mouse)")
    if args.compare and args.data is None:
        ap.error("--compare needs --data DATASET (the FE solutions)")
    if args.grasp and (args.compare or (args.place and not args.base)):
        ap.error("--grasp shows the liver of its data directory: no --compare, and --place "
                 "only with --base (a model placed on the liver of that directory)")
    if args.base and (args.compare or args.place is None):
        ap.error("--base takes the liver's file (--place) and no --compare")
    try:
        m, pred = build(args)
        if args.compare:
            png = compare(m, pred, args.data, args.sim, args.out if args.offscreen else None,
                          tuple(args.size))
            if png:
                print(png)
            return 0
        clim = m.colour_range()
        if args.offscreen:
            t = run_offscreen(m, clim, args.script, args.out, tuple(args.size))
            print(f"{log_prefix}: {t['frames']} frames, {t['gif']}; median inference "
                  f"{t['inference_ms_median']:.2f} ms, frame {t['frame_ms_median']:.1f} ms "
                  f"({t['fps_median']:.0f} fps) for {t['nodes_predicted']} nodes")
            return 0
        m.prefetch()   # a window waits for people: the solver process works meanwhile
        return run_window(m, clim, args.screenshot, tuple(args.size))
    # ViewerError (bad options, script, dataset), ValueError (a model or liver that cannot be
    # used), OSError (an output that cannot be written): each message names its file.
    except (ValueError, OSError) as exc:
        print(f"{log_prefix}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
