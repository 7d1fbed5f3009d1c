"""Shard contract: round trip, atomic writes, XDMF, and a validator that names each problem."""

import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from data_spec import (
    geometry_path,
    read_geometry,
    read_shard,
    shard_path,
    validate_dataset,
    write_geometry,
    write_shard,
)
from data_spec.atomic import atomic_path
from tests.fixtures import box_mesh, synthetic_dataset, synthetic_shard, write_test_scene


@pytest.fixture
def dataset(tmp_path):
    return synthetic_dataset(tmp_path / "ds", n_sims=3)


def test_round_trip(tmp_path):
    geo = box_mesh(2)
    write_geometry(geometry_path(tmp_path, geo.geometry_id), geo)
    s = synthetic_shard(geo, 7)
    write_shard(tmp_path, s)
    r = read_shard(shard_path(tmp_path, 7))
    for name in ("load_nodes", "forces", "fixed_nodes", "load_fractions", "output_nodes",
                 "displacement"):
        np.testing.assert_array_equal(getattr(r, name), getattr(s, name))
    assert r.material.K == s.material.K and r.status == "ok" and r.sim_index == 7
    assert [list(h) for h in r.stats.residual_history] == [list(h) for h in
                                                           s.stats.residual_history]
    g = read_geometry(geometry_path(tmp_path, geo.geometry_id))
    np.testing.assert_array_equal(g.points, geo.points)
    assert g.geometry_id == geo.geometry_id


def test_valid_dataset_and_cli(dataset):
    assert validate_dataset(dataset) == []
    out = subprocess.run([sys.executable, "-m", "data_spec", "validate", str(dataset)],
                         capture_output=True, text=True)
    assert out.returncode == 0 and "valid" in out.stdout


def test_xdmf_is_well_formed_and_points_at_existing_data(dataset):
    xdmf = shard_path(dataset, 1).with_suffix(".xdmf")
    root = ET.parse(xdmf).getroot()
    grids = root.findall("./Domain/Grid/Grid")
    assert len(grids) == 3
    assert [float(g.find("Time").get("Value")) for g in grids] == pytest.approx([1/3, 2/3, 1])
    for item in root.iter("DataItem"):
        if item.get("Format") == "HDF":
            fname, dset = item.text.split(":")
            with h5py.File(xdmf.parent / fname, "r") as f:
                dims = tuple(int(d) for d in item.get("Dimensions").split())
                assert f[dset].shape == dims


def _reseal(path):
    """Recompute the checksum after an edit: the file then looks as a faulty writer would
    have written it, so the validator's other checks are what is tested."""
    from data_spec.shard_layout import checksum, read_values

    with h5py.File(path, "a") as f:
        f.attrs["checksum"] = checksum(read_values(f))


def _problems_after(dataset, edit, reseal=True):
    edit(shard_path(dataset, 1))
    if reseal and h5py.is_hdf5(shard_path(dataset, 1)):
        try:
            _reseal(shard_path(dataset, 1))
        except (KeyError, OSError):  # an entry deleted, or the file truncated: no seal
            pass
    problems = validate_dataset(dataset)
    out = subprocess.run([sys.executable, "-m", "data_spec", "validate", str(dataset)],
                         capture_output=True, text=True)
    assert out.returncode == 1
    return problems


def test_missing_field(dataset):
    def edit(p):
        with h5py.File(p, "a") as f:
            del f["load/forces"]
    problems = _problems_after(dataset, edit)
    assert problems == [f"{shard_path(dataset, 1)}: missing dataset '/load/forces'"]


def test_wrong_shape(dataset):
    def edit(p):
        with h5py.File(p, "a") as f:
            d = f["displacement"][...]
            del f["displacement"]
            f["displacement"] = d[:, :-1, :]
    problems = _problems_after(dataset, edit)
    assert len(problems) == 1
    assert "'/displacement' has shape (3, 63, 3), expected (n_done, 64, 3)" in problems[0]


def test_nan_displacement(dataset):
    def edit(p):
        with h5py.File(p, "a") as f:
            f["displacement"][1, 5, 2] = np.nan
    problems = _problems_after(dataset, edit)
    assert problems == [f"{shard_path(dataset, 1)}: '/displacement' contains 1 NaN/inf value(s)"]


def test_one_flipped_bit_is_caught_by_the_checksum(dataset):
    """Uncompressed data has no HDF5 checksum of its own: one flipped bit in a label would
    pass every shape and finiteness check and train the model on a wrong value."""
    def edit(p):
        with h5py.File(p, "a") as f:
            forces = f["load/forces"][...]
            forces.view(np.uint64)[0, 0] ^= np.uint64(1) << np.uint64(40)
            f["load/forces"][...] = forces
    problems = _problems_after(dataset, edit, reseal=False)
    assert problems == [f"{shard_path(dataset, 1)}: checksum mismatch: the file was changed or "
                        "corrupted after it was written"]
    with pytest.raises(ValueError, match="checksum mismatch"):
        read_shard(shard_path(dataset, 1))


def test_missing_geometry_file(dataset):
    geo = next((dataset / "geometry").glob("*.h5"))
    geo.unlink()
    problems = validate_dataset(dataset)
    assert len(problems) == 3  # one per shard, each naming the missing file
    assert all(f"geometry file {geo} is missing" in p for p in problems)


def test_truncated_hdf5(dataset):
    def edit(p):
        data = p.read_bytes()
        p.write_bytes(data[: len(data) // 2])
    problems = _problems_after(dataset, edit)
    assert len(problems) == 1
    assert problems[0].startswith(f"{shard_path(dataset, 1)}: cannot open as HDF5 (truncated")


def test_failed_status_needs_reason_and_ok_needs_all_steps(dataset):
    def edit(p):
        with h5py.File(p, "a") as f:
            f.attrs["status"] = "failed"
    problems = _problems_after(dataset, edit)
    assert problems == [f"{shard_path(dataset, 1)}: status 'failed' without a failure_reason"]


def test_failed_shard_with_partial_steps_is_valid(tmp_path):
    geo = box_mesh(2)
    write_geometry(geometry_path(tmp_path, geo.geometry_id), geo)
    scene = write_test_scene(tmp_path, n_simulations=1)
    s = synthetic_shard(geo, 0, n_steps=4, scene_name=scene.name, scene_hash=scene.hash)
    s.displacement = s.displacement[:2]
    s.stats.newton_iterations = s.stats.newton_iterations[:2]
    s.stats.residual_norms = s.stats.residual_norms[:2]
    s.stats.cutbacks = s.stats.cutbacks[:2]
    s.stats.wall_time = s.stats.wall_time[:2]
    s.stats.residual_history = s.stats.residual_history[:2]
    s.status, s.failure_reason = "failed", "det F <= 0 after 8 cut-backs at load 0.625"
    write_shard(tmp_path, s)
    assert validate_dataset(tmp_path) == []
    s.status = "ok"
    write_shard(tmp_path, s)
    assert validate_dataset(tmp_path) == [
        f"{shard_path(tmp_path, 0)}: status 'ok' but 2 of 4 load steps stored"]


def test_atomic_write_leaves_nothing_on_error(tmp_path):
    final = tmp_path / "x.h5"
    with pytest.raises(RuntimeError):
        with atomic_path(final) as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("killed")
    assert os.listdir(tmp_path) == []


def test_leftover_temporary_is_reported(dataset):
    (dataset / "sims" / f"sim_000009.h5.tmp-{os.getpid()}").write_bytes(b"x")
    problems = validate_dataset(dataset)
    assert len(problems) == 1 and "leftover temporary file" in problems[0]


def test_a_dataset_grown_by_its_scenes_size_alone_stays_valid(dataset):
    """n_simulations raised from 3 to 5: the three shards (hashed at size 3) are the grown
    scene's once the dataset records its earlier size; any other edit is another scene."""
    import re

    from data_spec.grown import earlier_sizes, record_size
    from data_spec.scene import load_scene

    copy = dataset / "scene.toml"
    text = copy.read_text()
    copy.write_text(re.sub(r"(?m)^n_simulations = 3$", "n_simulations = 5", text))
    problems = validate_dataset(dataset, complete=False)
    assert len(problems) == 1 and "only n_simulations may change" in problems[0]
    record_size(dataset, 3)
    assert earlier_sizes(dataset) == [3]
    assert validate_dataset(dataset, complete=False) == []
    missing = validate_dataset(dataset)  # complete: simulations 3 and 4 have no shard yet
    assert len(missing) == 1 and "2 of the scene's 5 simulations have no shard" in missing[0]
    grown = load_scene(copy)
    assert grown.hash != grown.hash_at(3) and grown.hash_at(5) == grown.hash
    copy.write_text(re.sub(r"(?m)^n_simulations = 3$", "n_simulations = 5", text)
                    .replace("seed = 1", "seed = 2"))
    problems = validate_dataset(dataset, complete=False)
    assert len(problems) == 1 and "the scene was edited after the dataset was made" in problems[0]


def test_scene_file_must_be_there_and_unchanged(dataset):
    (dataset / "scene.toml").write_text((dataset / "scene.toml").read_text().replace(
        "seed = 1", "seed = 2"))
    problems = validate_dataset(dataset)
    assert len(problems) == 1 and "the scene was edited after the dataset was made" in problems[0]
    (dataset / "scene.toml").unlink()
    assert validate_dataset(dataset) == [f"{dataset / 'scene.toml'}: missing (every dataset "
                                         "keeps the scene that produced it)"]


def test_empty_directory(tmp_path):
    assert "no shards found" in validate_dataset(tmp_path)[0]


def test_every_layout_entry_is_documented():
    """The shard layout is declared once (data_spec/shard_layout.py); its README table must
    name every dataset and attribute of it."""
    from pathlib import Path

    from data_spec.shard_layout import LAYOUT

    readme = (Path(__file__).parents[2] / "data_spec" / "README.md").read_text()
    shard_doc = readme[readme.index("## Shard"):]
    for e in LAYOUT:
        assert f"`{e.name}`" in shard_doc, e.path


def test_a_grasp_shard_keeps_its_tools_and_a_version_2_shard_reads_as_none(tmp_path):
    """Schema 3 adds each tool's displacement and force per stored step; a shard written
    before (schema 2: no such entries, their checksum without them) is still read and
    validated, as a shard with no tool; a version this code does not know is refused."""
    from data_spec.shard_layout import checksum, entries, read_values

    geo = box_mesh(2)
    write_geometry(geometry_path(tmp_path, geo.geometry_id), geo)
    scene = write_test_scene(tmp_path, n_simulations=2)
    s = synthetic_shard(geo, 0, n_steps=3, scene_name=scene.name, scene_hash=scene.hash)
    s.tool_displacement = np.arange(9.0).reshape(3, 1, 3)
    s.reaction = 0.1 * np.arange(9.0).reshape(3, 1, 3)
    back = read_shard(write_shard(tmp_path, s))
    np.testing.assert_array_equal(back.tool_displacement, s.tool_displacement)
    np.testing.assert_array_equal(back.reaction, s.reaction)
    old = write_shard(tmp_path, synthetic_shard(geo, 1, n_steps=3, scene_name=scene.name,
                                                scene_hash=scene.hash))
    assert read_shard(old).reaction.shape == (3, 0, 3)   # written now: no tool
    with h5py.File(old, "r+") as f:   # as schema 2 wrote it
        del f["/load/tool_displacement"], f["/load/reaction"]
        f.attrs["schema_version"] = 2
        f.attrs["checksum"] = checksum({e.path: v for e, v in zip(
            entries(2), [read_values(f)[e.path] for e in entries(2)])}, 2)
    two = read_shard(old)
    assert two.reaction.shape == (3, 0, 3) and two.tool_displacement.shape == (3, 0, 3)
    assert validate_dataset(tmp_path) == []
    with h5py.File(old, "r+") as f:
        f.attrs["schema_version"] = 9
    with pytest.raises(ValueError, match="schema_version 9; this code reads"):
        read_shard(old)
