"""The manipulator: picking, dragging and clamping without a window; off-screen frames and the
FE comparison; the window itself under Xvfb.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from data_spec import list_shards, read_shard
from surrogate import load_predictor
from surrogate.config import get_config
from surrogate.manipulator import Manipulator
from surrogate.train import train_and_evaluate
from surrogate.viewer import ViewerError, compare, load_script, run_offscreen

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def run(synth_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("viewer_run")
    cfg = get_config("small", folds=2, epochs=4, hidden=[32, 32], batch_size=512)
    train_and_evaluate(synth_dir, out, cfg, log_fn=lambda m: None)
    return out


@pytest.fixture()
def m(run):
    return Manipulator(load_predictor(run / "model"))


def test_model_carries_its_surface_and_its_unseen_simulations(run, synth_dir):
    from data_spec import geometry_path, read_geometry

    pred = load_predictor(run / "model")
    s = read_shard(list_shards(synth_dir)[0])
    g = read_geometry(geometry_path(synth_dir, s.geometry_id))
    assert np.array_equal(pred.triangles, g.surface_triangles)
    unseen = pred.meta["unseen_simulations"]
    # inner_val_fraction 0.1 of 40 simulations: 4 held out of the final fit.
    assert len(unseen) == 4 and set(unseen) <= set(range(40))


def test_a_click_picks_the_nearest_surface_node_and_never_a_fixed_one(m):
    s = m.surface
    k = int(np.argmax(s.points[:, 0]))  # a node on the far face x = max
    node = int(s.nodes[k])
    assert m.pick(s.points[k] + [0.01, -0.02, 0.01]) == node
    assert m.handles[0].node == node
    fixed = int(m.fixed[0])
    assert m.pick(m.points[fixed]) == node  # the fixed region cannot be loaded
    deformed = s.points + [0.0, 0.0, 5.0]  # a click on the drawn (deformed) surface
    assert m.pick(deformed[k] + 0.01, deformed=deformed) == node
    with pytest.raises(ValueError, match="finite"):
        m.pick([np.nan, 0, 0])


def test_a_drag_sets_the_force_and_is_clamped_to_the_training_range(m):
    node = m.handles[0].node
    x = m.points[node]
    f = m.drag(x + [0.5 * m.drag_length, 0.0, 0.0])  # half the drag length: half f_max
    assert np.allclose(f, [0.5 * m.f_max, 0.0, 0.0])
    assert np.allclose(m.handle_position(), x + [0.5 * m.drag_length, 0.0, 0.0])
    f = m.drag(x + [0.0, 3.0 * m.drag_length, 4.0 * m.drag_length])  # 5x too far
    assert np.linalg.norm(f) == pytest.approx(m.f_max)
    assert np.allclose(f / m.f_max, [0.0, 0.6, 0.8])  # the direction is kept
    assert np.allclose(m.handle_position(), x + m.drag_length * np.array([0.0, 0.6, 0.8]))
    assert np.allclose(m.set_magnitude(0.25 * m.f_max), [0.0, 0.15 * m.f_max, 0.2 * m.f_max])
    with pytest.raises(ValueError, match="finite"):
        m.set_force([0.0, np.inf, 0.0])
    with pytest.raises(ValueError, match="1 force"):
        m.drag(x, handle=1)


def test_pushing_puts_the_sphere_on_the_other_side_of_the_node(m):
    x = m.points[m.handles[0].node]
    m.set_force([0.0, 0.0, 0.2 * m.f_max])
    above = m.handle_position()
    assert m.toggle_mode() == "push"
    assert np.allclose(m.handle_position() - x, -(above - x))  # the force is kept
    f = m.drag(x + [0.5 * m.drag_length, 0.0, 0.0])  # the push comes from +x: force along -x
    assert np.allclose(f, [-0.5 * m.f_max, 0.0, 0.0])
    m.set_force([0.0, 0.0, 0.0])
    i = m.surface.local([m.handles[0].node])[0]
    inward = -m.surface.normals()[i]
    assert np.allclose(m.set_magnitude(0.1), 0.1 * inward)  # a push goes into the liver
    assert np.dot(m.handle_position() - x, inward) < 0  # its sphere stands outside
    assert m.toggle_mode() == "pull"


def test_the_manipulators_prediction_is_the_predictors(run, m):
    pred = load_predictor(run / "model")
    node = m.handles[0].node
    m.set_force([0.1, -0.2, 0.15])
    frame = m.predict()
    direct = pred(np.array([[0.1, -0.2, 0.15]]), np.array([node]))
    assert frame.surface_u.shape == (m.surface.nodes.size, 3)
    assert np.allclose(frame.surface_u, direct[m.surface.nodes], rtol=1e-4, atol=1e-6)
    whole = Manipulator(pred, nodes="all")
    whole.handles[0].node = node
    whole.set_force([0.1, -0.2, 0.15])
    all_frame = whole.predict()
    assert all_frame.u.shape == (m.points.shape[0], 3)
    assert np.allclose(all_frame.surface_u, frame.surface_u, rtol=1e-4, atol=1e-6)
    assert np.abs(frame.surface_u).max() > 0


def test_default_handles_are_far_from_the_fixed_region_and_from_each_other(m):
    a, b = m.default_nodes(2)
    fixed = m.points[m.fixed]
    d = np.linalg.norm(m.surface.points[:, None] - fixed[None], axis=2).min(axis=1)
    assert np.min(np.linalg.norm(fixed - m.points[a], axis=1)) == pytest.approx(d.max())
    assert a != b and np.linalg.norm(m.points[a] - m.points[b]) > 0.5 * m.surface.size / 2


def _frame(png):
    from PIL import Image

    return np.asarray(Image.open(png).convert("RGB")).astype(int)


def test_off_screen_frames_are_drawn_and_differ_between_forces(m, tmp_path):
    node = m.handles[0].node
    script = tmp_path / "forces.json"
    script.write_text(json.dumps({"fps": 4, "frames": [
        {"nodes": [node], "forces": [[0.0, 0.0, 0.3]]},
        {"nodes": [node], "forces": [[0.0, 0.0, -0.3]]}]}))
    import time

    t0 = time.perf_counter()
    t = run_offscreen(m, m.colour_range(), script, tmp_path / "out", (320, 240))
    wall = time.perf_counter() - t0
    a, b = _frame(tmp_path / "out" / "frame_0000.png"), _frame(tmp_path / "out" / "frame_0001.png")
    assert a.shape == (240, 320, 3)
    assert np.any(np.abs(a - 255) > 30, axis=2).mean() > 0.05  # the liver is there
    assert np.abs(a - b).mean() > 1.0  # another force, another picture
    from PIL import Image

    with Image.open(t["gif"]) as gif:
        assert gif.n_frames == 2
    # the timings are of these frames: inference is part of a frame, and the frames fit in the
    # wall-clock time of the whole run (two frames: their median is their mean)
    assert 0 < t["inference_ms_median"] <= t["frame_ms_median"]
    assert t["frames"] == 2 and t["frames"] / t["fps_median"] <= wall


@pytest.mark.parametrize("frames, message", [
    ([{"nodes": [0], "forces": [[0, 0]]}], r"frames\[0\]: forces: expected 1 finite"),
    ([{"nodes": [0], "forces": [[0, 0, "x"]]}], r"frames\[0\]: forces"),
    ([{"nodes": [10 ** 6], "forces": [[0, 0, 0]]}], r"frames\[0\]: nodes: expected 1 node"),
    ([{"forces": [[0, 0, 0]], "pull": 1}], r"frames\[0\]: unknown key\(s\) \['pull'\]"),
    ([{"nodes": [0], "forces": [[0, 0, 0]]}], r"frames\[0\]: nodes: \[0\] are in the fixed"),
    ([{"forces": [[0, 0, 0]], "steps": 0}], r"frames\[0\]: steps"),
    ([{"forces": [[0, 0, 0]], "inputs": [1.0]}], r"frames\[0\]: inputs: expected 0 numbers"),
    ([], "non-empty list 'frames'"),
])
def test_bad_scripts_are_refused_naming_file_and_key(m, tmp_path, frames, message):
    script = tmp_path / "bad.json"
    script.write_text(json.dumps({"frames": frames}))
    with pytest.raises(ViewerError, match=message) as err:
        load_script(script, m)
    assert str(script) in str(err.value)


def test_script_entries_are_interpolated(m, tmp_path):
    script = tmp_path / "s.json"
    script.write_text(json.dumps({"frames": [
        {"points": [m.points[m.handles[0].node].tolist()], "forces": [[0, 0, 0.2]], "steps": 2},
        {"forces": [[0.2, 0, 0]], "steps": 2}]}))
    frames, fps = load_script(script, m)
    assert fps == 10 and len(frames) == 4
    assert np.allclose([f["forces"][0] for f in frames],
                       [[0, 0, 0.1], [0, 0, 0.2], [0.1, 0, 0.1], [0.2, 0, 0]])
    assert all(f["nodes"] == [m.handles[0].node] for f in frames)


def test_comparison_shows_an_unseen_simulation(run, synth_dir, m, tmp_path, capsys):
    pred = load_predictor(run / "model")
    png = compare(m, pred, synth_dir, None, tmp_path, (300, 240))
    sim = int(png.stem.removeprefix("compare_sim"))
    assert sim in pred.meta["unseen_simulations"]
    img = _frame(png)
    assert img.shape[1] == 3 * 560 and np.any(np.abs(img - 255) > 30, axis=2).mean() > 0.05
    assert "surface mean error" in capsys.readouterr().out
    with pytest.raises(ViewerError, match="--sim 999"):
        compare(m, pred, synth_dir, 999, tmp_path, (300, 240))


def test_command_line_refuses_a_directory_without_a_model(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "surrogate.viewer", str(tmp_path),
                           "--offscreen", "--out", str(tmp_path / "o")], capture_output=True,
                          text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2 and "no model.json" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_command_line_refuses_an_output_that_is_a_file(run, tmp_path):
    out = tmp_path / "frames"
    out.write_text("a file, not a directory")
    proc = subprocess.run([sys.executable, "-m", "surrogate.viewer", str(run), "--offscreen",
                           "--out", str(out)], capture_output=True, text=True, timeout=300,
                          cwd=ROOT)
    assert proc.returncode == 2 and str(out) in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.fixture()
def xvfb():
    """A private X display; the test is skipped, with the reason, where none can start."""
    exe = shutil.which("Xvfb")
    if exe is None:
        reason = "Xvfb is not installed (Debian package xvfb; make setup installs it)"
        print(reason)
        pytest.skip(reason)
    r, w = os.pipe()
    proc = subprocess.Popen([exe, "-displayfd", str(w), "-screen", "0", "1280x1024x24",
                             "-nolisten", "tcp"], pass_fds=(w,), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    os.close(w)
    number = b""
    deadline = time.time() + 20
    while time.time() < deadline and not number.endswith(b"\n"):
        chunk = os.read(r, 16)
        if not chunk:
            break
        number += chunk
    os.close(r)
    if not number.strip():
        proc.kill()
        reason = "Xvfb did not start a display here"
        print(reason)
        pytest.skip(reason)
    yield f":{number.decode().strip()}"
    proc.terminate()
    proc.wait(timeout=10)


def test_the_window_opens_and_closes_under_xvfb(run, xvfb, tmp_path):
    shot = tmp_path / "window.png"
    env = {**os.environ, "DISPLAY": xvfb}
    env.pop("VTK_DEFAULT_OPENGL_WINDOW", None)
    proc = subprocess.run([sys.executable, "-m", "surrogate.viewer", str(run), "--screenshot",
                           str(shot), "--size", "640", "480"], capture_output=True, text=True,
                          timeout=300, cwd=ROOT, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "window opened" in proc.stdout
    # The window's callbacks: the pick kept the default node, the drag 1.5 drag lengths out
    # was clamped to the training maximum, and the slider and the sphere followed.
    pred = load_predictor(run / "model")
    m = Manipulator(pred)
    fmax = f"{pred.force_norm_max:.4f} N"
    assert f"picked node {m.handles[0].node}," in proc.stdout
    assert f"dragged: force {fmax} (training max {fmax}), slider {fmax}" in proc.stdout
    assert f"sphere at {m.drag_length:.2f} mm (drag length {m.drag_length:.2f} mm)" \
        in proc.stdout
    assert "Traceback" not in proc.stderr and "issue in callback" not in proc.stderr, \
        proc.stderr
    img = _frame(shot)
    assert img.shape == (480, 640, 3)
    assert np.any(np.abs(img - 255) > 30, axis=2).mean() > 0.05


class _TwoForceMaterialModel:
    """A stand-in predictor with two forces and a material input: u = (f1 + f2) * c1 at every
    node, so what the manipulator hands over can be read off the prediction.
    """

    def __init__(self):
        from surrogate.features import FeatureSpec
        from tests.fixtures import box_mesh

        g = box_mesh(3, (30.0, 20.0, 10.0))
        self.spec = FeatureSpec(n_loads=2, material_dim=3)
        self.points, self.fixed = g.points, g.regions["x0"]
        self.triangles, self.output_nodes = g.surface_triangles, np.arange(g.n_nodes)
        self.force_norm_max, self.design = 0.4, "nodewise"
        self.meta = {"training_range": {"extra_min": [1e-3, 6.0, 0.2],
                                        "extra_max": [5e-3, 12.0, 2.0]}}
        self.calls = []

    def __call__(self, forces, load_nodes, nodes=None, material=None, geometry=None):
        self.calls.append((forces.copy(), load_nodes.copy(), material.copy()))
        n = self.points.shape[0] if nodes is None else len(nodes)
        return np.broadcast_to(forces.sum(axis=0) * material[0], (n, 3)).copy()


def test_two_forces_and_a_material_reach_the_model_as_set():
    pred = _TwoForceMaterialModel()
    m = Manipulator(pred)
    assert len(m.handles) == 2 and m.handles[0].node != m.handles[1].node
    assert [i.name for i in m.inputs] == ["c1 (MPa)", "m1", "K (MPa)"]
    assert [i.value for i in m.inputs] == pytest.approx([3e-3, 9.0, 1.1])  # mid-range
    first = m.handles[0].node
    s = m.surface
    k = int(np.argmin(np.linalg.norm(s.points - [30.0, 0.0, 0.0], axis=1)))
    assert m.pick(s.points[k], handle=1) == s.nodes[k] and m.handles[0].node == first
    m.drag(m.points[s.nodes[k]] + [0.0, 0.0, m.drag_length], handle=1)  # f_max along z
    m.set_force([0.1, 0.0, 0.0], handle=0)
    assert m.set_input(0, 1.0) == 5e-3  # clamped to the training range
    u = m.predict().surface_u
    forces, nodes, material = pred.calls[-1]
    assert np.allclose(forces, [[0.1, 0.0, 0.0], [0.0, 0.0, 0.4]])
    assert nodes.tolist() == [first, s.nodes[k]]
    assert np.allclose(material, [5e-3, 9.0, 1.1])
    assert np.allclose(u, [0.1 * 5e-3, 0.0, 0.4 * 5e-3])
    with pytest.raises(ValueError, match="2 force"):
        m.set_force([0, 0, 0], handle=2)
