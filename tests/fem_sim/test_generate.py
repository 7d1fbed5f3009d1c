"""Batch generation under mpirun: same shards for any rank layout, resumable after SIGKILL,
failures recorded without killing the batch, bad scenes rejected on every rank before any work."""

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from data_spec import list_shards, read_shard, validate_dataset
from data_spec.atomic import leftover_temporaries
from fem_sim.batch.chunked import mpirun_env

pytestmark = pytest.mark.mpi  # every test here spawns mpirun

ROOT = Path(__file__).parents[2]
TINY = ROOT / "data_spec" / "scenes" / "tiny_scene1.toml"
ENV = mpirun_env(PYTHONPATH=str(ROOT))


def generate(scene, out, n=1, r=1, extra=(), timeout=600, **kw):
    """Run generate under mpirun; a hang fails the test at ``timeout`` seconds."""
    cmd = ["mpirun", "-n", str(n), sys.executable, "-m", "fem_sim", "generate", str(scene),
           "--out", str(out), "--ranks-per-sim", str(r), "--no-progress", *extra]
    return subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=timeout, **kw)


def displacements(d):
    return {p.name: read_shard(p).displacement for p in list_shards(d)}


def session_members(sid):
    """Live processes of session ``sid`` (from /proc; zombies have released their files)."""
    pids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # the process ended while we looked
            continue
        fields = text[text.rindex(")") + 2:].split()  # state ppid pgrp session ...
        if int(fields[3]) == sid and fields[0] != "Z":
            pids.append(int(stat.parent.name))
    return pids


def kill_session(sid, timeout=30.0):
    """SIGKILL a whole mpirun job, as a batch scheduler does, and wait until it is gone.

    ``killpg`` on mpirun is not enough: Open MPI starts every rank in its own process group,
    so the ranks outlive a killed mpirun and go on working (and rank 0 goes on holding the
    dataset's lock). The job started with ``start_new_session``, so its session id is
    mpirun's pid and every rank carries it.
    """
    t0 = time.time()
    while (pids := session_members(sid)) and time.time() - t0 < timeout:
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.05)
    assert not session_members(sid), f"processes of session {sid} survived SIGKILL"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    res = generate(TINY, out, n=1)
    assert res.returncode == 0, res.stderr
    return out


def test_reference_dataset_is_valid_and_rerun_skips_everything(reference):
    assert validate_dataset(reference) == []
    assert len(list_shards(reference)) == 4
    with h5py.File(list_shards(reference)[0], "r") as f:
        assert f.attrs["status"] == "ok" and f["displacement"].shape[0] == 3
    res = generate(TINY, reference, n=1)
    assert "0 simulated (0 failed), 4 skipped" in res.stdout


@pytest.mark.parametrize("n, r", [(2, 1), (2, 2)])
def test_same_shards_for_any_rank_layout(reference, tmp_path, n, r):
    res = generate(TINY, tmp_path, n=n, r=r)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(tmp_path) == []
    a, b = displacements(reference), displacements(tmp_path)
    assert a.keys() == b.keys()
    # One rank per simulation runs the same code path as the reference: the same numbers.
    # Two ranks per simulation factorise with PETSc's MUMPS instead of the serial float32
    # LDL^T (solver.factorization = "auto"), so Newton takes other iterates to the same
    # solution: equal to the Newton tolerance. Measured between the two paths: up to 6.1e-8 of
    # max |u| at the default rtol 1e-6, 1.25e-5 at rtol 1e-5 (Newton lands anywhere below
    # the tolerance): the bound is 10x the scene's tolerance (tiny_scene1 keeps the default
    # rtol 1e-6), written out so that a looser default fails here.
    tol = 1e-10 if r == 1 else 1e-5
    for k in a:
        err = np.abs(b[k] - a[k]).max() / np.abs(a[k]).max()
        assert err <= tol, (k, err)


def test_rerun_skips_valid_and_redoes_corrupt(reference, tmp_path):
    shutil.copytree(reference, tmp_path / "d")
    d = tmp_path / "d"
    victim = list_shards(d)[2]
    victim.write_bytes(victim.read_bytes()[:500])  # corrupt
    list_shards(d)[0].unlink()                     # missing
    res = generate(TINY, d, n=2)
    assert res.returncode == 0, res.stderr
    assert "2 simulated (0 failed), 2 skipped" in res.stdout
    assert validate_dataset(d) == []
    a, b = displacements(reference), displacements(d)
    for k in a:
        np.testing.assert_allclose(b[k], a[k], rtol=0, atol=1e-10 * np.abs(a[k]).max())


def test_a_shard_of_another_mesh_or_fixed_region_is_run_again(reference, tmp_path):
    """A resumed batch keeps a shard only if it is of the liver the scene now gives that
    simulation: its mesh (a liver file prepared again may mesh otherwise) and its fixed nodes
    (a registration may fix others on the same mesh). Two valid shards (checksums right),
    one of a jiggled copy of the mesh and one with a fixed node fewer, are run again; the
    dataset ends as the reference."""
    import dataclasses

    from data_spec import geometry_path, read_geometry, write_geometry, write_shard

    d = tmp_path / "d"
    shutil.copytree(reference, d)
    a, b = list_shards(d)[1], list_shards(d)[2]
    sa, sb = read_shard(a), read_shard(b)
    g = read_geometry(geometry_path(d, sa.geometry_id))
    other = dataclasses.replace(g, points=g.points + 1e-3)
    write_geometry(geometry_path(d, other.geometry_id), other)
    a.unlink()
    b.unlink()
    write_shard(d, dataclasses.replace(sa, geometry_id=other.geometry_id))
    write_shard(d, dataclasses.replace(sb, fixed_nodes=sb.fixed_nodes[1:]))
    assert validate_dataset(d) == []  # valid shards, of another liver than the scene's
    res = generate(TINY, d, n=1)
    assert res.returncode == 0, res.stderr
    assert "2 simulated (0 failed), 2 skipped" in res.stdout, res.stdout
    ref, now = displacements(reference), displacements(d)
    for k in ref:
        np.testing.assert_allclose(now[k], ref[k], rtol=0, atol=1e-10 * np.abs(ref[k]).max())


def test_a_geometry_file_with_another_fixed_region_is_written_again(reference):
    """The same mesh with another region (a liver registered again) is not the file's."""
    import dataclasses

    from data_spec import read_geometry
    from fem_sim.batch.generate import _geometry_file_ok

    path = next((reference / "geometry").glob("*.h5"))
    g = read_geometry(path)
    assert _geometry_file_ok(path, g)
    name = next(iter(g.regions), "vena_cava")
    moved = dataclasses.replace(g, regions={**g.regions, name: np.arange(3)})
    assert not _geometry_file_ok(path, moved)


def test_ranks_waiting_for_rank_0_sleep_instead_of_spinning():
    """While rank 0 prepares a population's livers (minutes), the other ranks wait in
    generate.quiet_wait: rank 0 busy for 2 s, rank 1's CPU time over its wait stays a small
    part of it (a blocking MPI barrier spins: about 2 s)."""
    code = ("import time\n"
            "from mpi4py import MPI\n"
            "from fem_sim.batch.generate import quiet_wait\n"
            "w = MPI.COMM_WORLD\n"
            "t = time.process_time()\n"
            "if w.rank == 0:\n"
            "    time.sleep(2.0)\n"
            "quiet_wait(w)\n"
            "if w.rank == 1:\n"
            "    print('cpu', time.process_time() - t, flush=True)\n")
    res = subprocess.run(["mpirun", "-n", "2", sys.executable, "-c", code], env=ENV,
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    cpu = float(re.search(r"cpu ([\d.e-]+)", res.stdout).group(1))
    assert cpu < 0.5, cpu


@pytest.mark.slow
def test_sigkill_midway_then_resume(reference, tmp_path):
    scene = tmp_path / "many.toml"
    scene.write_text(TINY.read_text().replace("n_simulations = 4", "n_simulations = 12"))
    d = tmp_path / "d"
    cmd = ["mpirun", "-n", "2", sys.executable, "-m", "fem_sim", "generate", str(scene),
           "--out", str(d), "--no-progress"]
    proc = subprocess.Popen(cmd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    t0 = time.time()
    while len(list_shards(d)) < 3 and time.time() - t0 < 120:
        time.sleep(0.05)
    kill_session(proc.pid)
    proc.wait()
    assert len(list_shards(d)) < 12
    res = generate(scene, d, n=2)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(d) == []
    assert leftover_temporaries(d) == []
    full = tmp_path / "full"
    assert generate(scene, full, n=1).returncode == 0
    a, b = displacements(full), displacements(d)
    assert a.keys() == b.keys() and len(a) == 12
    for k in a:
        np.testing.assert_allclose(b[k], a[k], rtol=0, atol=1e-10 * np.abs(a[k]).max())


@pytest.mark.slow
def test_failing_case_is_recorded_and_batch_finishes(tmp_path):
    """A force far beyond what the soft liver can carry in the allowed cut-backs (2000x the
    nominal force; at 1000x two of the four draws converge since increments are sized by the
    predictor's error, and at 10000x all fail at the first predictor, not in Newton)."""
    scene = tmp_path / "hard.toml"
    text = TINY.read_text().replace("magnitude = 0.4", "magnitude = 800.0")
    text = text.replace('linear_solver = "direct"', 'linear_solver = "direct"\nmax_cutbacks = 2')
    scene.write_text(text)
    sweep = ("--max-failure-rate", "1")  # a sweep of extremes may fail often: exit 0
    res = generate(scene, tmp_path / "d", n=2, extra=sweep)
    assert res.returncode == 0, res.stderr
    assert "failed)" in res.stdout and "(0 failed)" not in res.stdout
    shards = [read_shard(p) for p in list_shards(tmp_path / "d")]
    failed = [s for s in shards if s.status == "failed"]
    assert failed and all(s.failure_reason for s in failed)
    assert all(np.isfinite(s.displacement).all() for s in shards)
    assert validate_dataset(tmp_path / "d") == []
    # failed shards are kept on a re-run, and redone only on request
    again = generate(scene, tmp_path / "d", n=2)
    assert "0 simulated (0 failed), 4 skipped" in again.stdout
    retry = generate(scene, tmp_path / "d", n=2, extra=("--retry-failed", *sweep))
    assert f"{len(failed)} simulated ({len(failed)} failed)" in retry.stdout
    # with the default threshold, a batch where most simulations fail is an error
    n = len(failed)
    assert n >= 3  # most of the 4: seeded draws, the same on every machine
    strict = generate(scene, tmp_path / "d", n=2, extra=("--retry-failed",))
    assert strict.returncode == 3, strict.stderr
    assert f"{n} of {n} simulations failed, more than --max-failure-rate 0.5" in strict.stderr
    assert re.search(r" x (Newton (did not converge in #|is not converging|stalled at load #)"
                     r"|line search failed at load #)", strict.stderr), \
        strict.stderr


def test_bad_scene_exits_nonzero_on_every_rank_before_any_work(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text(TINY.read_text().replace("magnitude = 0.4", "magnitude = -0.4"))
    res = generate(scene, tmp_path / "d", n=2)  # a hang would hit generate()'s timeout
    assert res.returncode != 0
    assert "loads.magnitude: expected a number > 0" in res.stderr
    assert not (tmp_path / "d" / "sims").exists()
    # the corrected scene is then accepted in the same directory
    scene.write_text(TINY.read_text())
    assert generate(scene, tmp_path / "d", n=2).returncode == 0
    assert validate_dataset(tmp_path / "d") == []


def test_directory_of_another_scene_is_refused(reference, tmp_path):
    other = tmp_path / "other.toml"
    other.write_text(TINY.read_text().replace("seed = 1\n", "seed = 7\n"))
    res = generate(other, reference, n=1)
    assert res.returncode == 2 and "holds a dataset of another scene" in res.stderr


def test_raising_n_simulations_grows_the_dataset_and_keeps_its_shards(reference, tmp_path):
    """The same scene with 6 simulations instead of 4: generate makes simulations 4 and 5
    only, the dataset validates; back at 4 it is refused (data_spec/grown.py)."""
    d = tmp_path / "d"
    shutil.copytree(reference, d)
    before = {p.name: p.stat().st_mtime_ns for p in list_shards(d)}
    grown = tmp_path / "grown.toml"
    grown.write_text(TINY.read_text().replace("n_simulations = 4", "n_simulations = 6"))
    res = generate(grown, d, n=1)
    assert res.returncode == 0, res.stderr
    assert "2 simulated (0 failed), 4 skipped" in res.stdout
    assert validate_dataset(d) == []
    assert {p.name: p.stat().st_mtime_ns for p in list_shards(d)[:4]} == before
    res = generate(TINY, d, n=1)  # back at 4: it would leave shards 4 and 5 past the end
    assert res.returncode == 2 and "would leave shards past its end" in res.stderr
    assert validate_dataset(d) == []


def test_mesh_with_a_floating_piece_is_refused_before_any_work(tmp_path):
    """A volume mesh with a piece that touches no fixed node would make every simulation
    singular: generate refuses it on every rank, names the file and the reason, and writes
    no shard."""
    import meshio

    from fem_sim.geometry.phantom import make_phantom

    g = make_phantom(0, 20.0)
    far = np.array([[500.0, 0, 0], [510, 0, 0], [500, 10, 0], [500, 0, 10]])
    meshio.write(tmp_path / "liver.vtu",
                 meshio.Mesh(np.concatenate([g.points, far]),
                             [("tetra", np.concatenate([g.cells, [np.arange(4) + g.n_nodes]]))]))
    scene = tmp_path / "floating.toml"
    scene.write_text(TINY.read_text().replace(
        'source = "phantom"      # the embedded liver phantom: no external file needed\n'
        "phantom_seed = 0\n", 'source = "file"\npath = "liver.vtu"\n'))
    res = generate(scene, tmp_path / "d", n=2)
    assert res.returncode == 2, res.stderr
    assert "touch no fixed node" in res.stderr and "liver.vtu" in res.stderr
    assert not (tmp_path / "d" / "sims").exists() or not list((tmp_path / "d" / "sims").iterdir())


def test_a_second_run_on_the_same_directory_is_refused(tmp_path):
    """Two generate runs on one --out would overwrite each other: the directory is locked
    (flock, released by the kernel when the holder dies) and the second run names the first."""
    from fem_sim.batch.lock import DirectoryLock

    lock = DirectoryLock(tmp_path / "d").acquire()
    try:
        res = generate(TINY, tmp_path / "d", n=2)
        assert res.returncode == 2
        assert "another generate run is using this directory" in res.stderr
        assert f"pid {os.getpid()}" in res.stderr
    finally:
        lock.release()
    assert generate(TINY, tmp_path / "d", n=2).returncode == 0


@pytest.mark.parametrize("content", [b"", b"garbage, not a mesh\n"])
def test_unreadable_mesh_file_ends_every_rank_with_a_message(tmp_path, content):
    """meshio calls sys.exit on some unreadable files; that must not leave ranks waiting."""
    (tmp_path / "liver.vtu").write_bytes(content)
    scene = tmp_path / "s.toml"
    scene.write_text(TINY.read_text().replace(
        'source = "phantom"      # the embedded liver phantom: no external file needed\n'
        "phantom_seed = 0\n", 'source = "file"\npath = "liver.vtu"\n'))
    res = generate(scene, tmp_path / "d", n=2, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "liver.vtu" in res.stderr


def test_a_rank_that_fails_after_planning_aborts_all_ranks(tmp_path):
    """A shard that cannot be written on one rank (a directory where its XDMF file should
    go) ends the whole run with the rank's message instead of a hang."""
    (tmp_path / "d" / "sims" / "sim_000003.xdmf").mkdir(parents=True)
    res = generate(TINY, tmp_path / "d", n=2, timeout=120)
    assert res.returncode != 0
    assert "aborting all 2 ranks" in res.stderr


def test_leftover_temporaries_are_removed_on_resume(reference, tmp_path):
    d = tmp_path / "d"
    shutil.copytree(reference, d)
    (d / "sims" / "sim_000001.h5.tmp-12345").write_bytes(b"half a shard")
    assert validate_dataset(d) != []
    res = generate(TINY, d, n=1)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(d) == []


@pytest.mark.parametrize("extra, n, message", [
    (("--only=-2..1",), 2, "--only -2..1: expected 0 <= I < J"),
    (("--ranks-per-sim", "3"), 2, "--ranks-per-sim 3 does not divide the 2 MPI ranks"),
])
def test_bad_command_line_is_refused_before_anything_is_written(tmp_path, extra, n, message):
    res = generate(TINY, tmp_path / "d", n=n, extra=extra, timeout=120)
    assert res.returncode == 2 and message in res.stderr, res.stderr
    assert not (tmp_path / "d" / "scene.toml").exists()


def test_the_locking_free_element_from_a_scene(reference, tmp_path):
    """solver.element = 'anp': a valid dataset whose shards record the element, with larger
    displacements than P1's (P1 locks at K/mu = 200: it is too stiff); several ranks per
    simulation are refused before anything is written (the element is serial)."""
    scene = tmp_path / "anp.toml"
    scene.write_text(TINY.read_text().replace('linear_solver = "direct"',
                                              'linear_solver = "direct"\nelement = "anp"'))
    res = generate(scene, tmp_path / "d", n=2)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(tmp_path / "d") == []
    ours, p1 = displacements(tmp_path / "d"), displacements(reference)
    assert ours.keys() == p1.keys()
    for name in ours:
        assert read_shard(tmp_path / "d" / "sims" / name).stats.info["element"] == "anp"
        a, b = np.abs(ours[name][-1]).max(), np.abs(p1[name][-1]).max()
        assert a > 1.05 * b, (name, a, b)
    res = generate(scene, tmp_path / "e", n=2, r=2, timeout=120)
    assert res.returncode == 2 and "not a supported combination" in res.stderr
    assert "on 2 ranks per simulation" in res.stderr, res.stderr
    assert not (tmp_path / "e" / "scene.toml").exists()


def test_a_combination_the_rule_table_lacks_is_refused_before_any_file(tmp_path):
    """element 'anp' with linear_solver 'gamg': refused by the scene check (the one rule
    table), naming the keys; no scene.toml, geometry or shard is written."""
    scene = tmp_path / "anp_gamg.toml"
    scene.write_text(TINY.read_text().replace(
        'linear_solver = "direct"', 'linear_solver = "gamg"\nelement = "anp"'))
    res = generate(scene, tmp_path / "d", n=2, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "element = 'anp'" in res.stderr and "linear_solver = 'gamg'" in res.stderr
    assert "not a supported combination" in res.stderr
    assert not (tmp_path / "d").exists() or not any((tmp_path / "d").iterdir())


def test_truncated_geometry_file_is_rewritten_on_resume(reference, tmp_path):
    d = tmp_path / "d"
    shutil.copytree(reference, d)
    geo = next((d / "geometry").glob("*.h5"))
    geo.write_bytes(geo.read_bytes()[:1000])
    assert validate_dataset(d) != []
    res = generate(TINY, d, n=2)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(d) == []


def test_an_option_petsc_does_not_know_fails_the_batch_with_the_reason(tmp_path):
    """Every simulation fails on an unknown PETSc preconditioner: the batch must not exit 0
    as if the dataset were fine; it exits 3 and shows PETSc's complaint."""
    scene = tmp_path / "s.toml"
    scene.write_text(TINY.read_text().replace(
        'linear_solver = "direct"',
        'linear_solver = "direct"\npetsc_options = { pc_type = "no_such_pc" }'))
    res = generate(scene, tmp_path / "d", n=2, timeout=120)
    assert res.returncode == 3, res.stderr
    assert "4 of 4 simulations failed" in res.stderr and "PCSetFromOptions" in res.stderr
    assert validate_dataset(tmp_path / "d") == []  # failures recorded, nothing half-written


def test_the_gamg_route_solves_the_tiny_scene_as_the_direct_one_does(reference, tmp_path):
    """linear_solver = 'gamg' (CG + GAMG with the rigid-body modes) on tiny_scene1 (P1,
    20 mm, K/mu = 200): every simulation converges and gives the direct solver's displacement
    (both to the Newton tolerance 1e-6); a misspelt option in petsc_options is warned about
    once per run, not once per simulation."""
    scene = tmp_path / "gamg.toml"
    scene.write_text(TINY.read_text().replace(
        'linear_solver = "direct"',
        'linear_solver = "gamg"\npetsc_options = { bogus_option_xyz = 1 }'))
    res = generate(scene, tmp_path / "d", n=1)
    assert res.returncode == 0, res.stderr
    assert validate_dataset(tmp_path / "d") == []
    ours, direct = displacements(tmp_path / "d"), displacements(reference)
    assert ours.keys() == direct.keys() and len(ours) == 4
    for name in ours:
        ref = direct[name][-1]
        assert np.abs(ours[name][-1] - ref).max() <= 1e-4 * np.abs(ref).max(), name
    assert res.stderr.count("bogus_option_xyz") == 1, res.stderr


def test_the_rule_tables_message_says_each_row_once(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text(TINY.read_text().replace(
        'linear_solver = "direct"', 'linear_solver = "gamg"\nfactorization = "pardiso"'))
    res = generate(scene, tmp_path / "d", n=1, timeout=120)
    assert res.returncode == 2 and "not a supported combination" in res.stderr, res.stderr
    for line in res.stderr.splitlines():
        assert "one rank: one rank" not in line and line.count("any ranks") <= 1, line


def test_an_out_that_is_a_file_is_refused_naming_the_flag(tmp_path):
    (tmp_path / "a_file").write_text("")
    res = generate(TINY, tmp_path / "a_file", n=1, timeout=120)
    assert res.returncode == 2, res.stderr
    assert "--out" in res.stderr and "is a file; expected the dataset's directory" in res.stderr
    assert "Errno" not in res.stderr


def linear(scene, out, *extra):
    cmd = [sys.executable, "-m", "fem_sim", "linear", str(scene), "--out", str(out), *extra]
    return subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=600)


def test_small_strain_responses_of_the_scenes_loads_and_drawn_ones(reference, tmp_path):
    """fem_sim linear on the dataset's own scene: the responses of its 4 simulations' loads
    (the same draws as generate's shards) and of 3 drawn cases, zero on the fixed region; the
    first load step of each shard (fraction 1/3) near a third of its linear response, its last
    not as near (the liver stiffens).
    """
    out = tmp_path / "d"
    shutil.copytree(reference, out)
    res = linear(TINY, out, "--synthetic", "3")
    assert res.returncode == 0, res.stderr
    from data_spec.linear_fields import SYNTHETIC_FIRST, linear_fields_path, read_linear_fields

    lf = read_linear_fields(linear_fields_path(out))
    assert lf.case_index.tolist() == [0, 1, 2, 3, *range(SYNTHETIC_FIRST, SYNTHETIC_FIRST + 3)]
    assert lf.synthetic.tolist() == [4, 5, 6]
    for sh in map(read_shard, list_shards(out)):
        row = lf.rows([sh.sim_index])[0]
        np.testing.assert_array_equal(lf.load_nodes[row], sh.load_nodes)
        np.testing.assert_allclose(lf.forces[row], sh.forces)
        u = lf.displacement[row][np.searchsorted(lf.output_nodes, sh.output_nodes)]
        assert np.all(u[np.isin(sh.output_nodes, sh.fixed_nodes)] == 0.0)
        gaps = [np.linalg.norm(d - lam * u, axis=1).mean() / np.linalg.norm(d, axis=1).mean()
                for d, lam in zip(sh.displacement, sh.load_fractions)]
        assert gaps[0] < 0.1 and gaps[-1] > gaps[0]
    assert validate_dataset(out) == []   # the file beside the shards breaks nothing


def test_second_order_responses_close_most_of_the_first_steps_gap(reference, tmp_path):
    """fem_sim linear --order 2: the same linear responses as order 1, and
    lam u1 + lam^2 u2 nearer each shard's first load step (fraction 1/3) than lam u1 is (the
    gap left is third order in the load).
    """
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    out = tmp_path / "d"
    shutil.copytree(reference, out)
    assert linear(TINY, out).returncode == 0
    first = read_linear_fields(linear_fields_path(out))
    res = linear(TINY, out, "--order", "2")
    assert res.returncode == 0, res.stderr
    lf = read_linear_fields(linear_fields_path(out))
    assert first.order == 1 and lf.order == 2
    np.testing.assert_allclose(lf.displacement, first.displacement,
                               atol=1e-6 * np.abs(first.displacement).max())
    for sh in map(read_shard, list_shards(out)):
        row = lf.rows([sh.sim_index])[0]
        cols = np.searchsorted(lf.output_nodes, sh.output_nodes)
        u1, u2 = lf.displacement[row][cols], lf.second_order[row][cols]
        lam, d = sh.load_fractions[0], sh.displacement[0]
        one = np.linalg.norm(d - lam * u1, axis=1).mean()
        two = np.linalg.norm(d - lam * u1 - lam**2 * u2, axis=1).mean()
        assert two < 0.2 * one, (sh.sim_index, one, two)


def test_greens_function_gives_every_nodal_loads_response(reference, tmp_path):
    """fem_sim linear --green: a unit response per axis at every surface node off the fixed
    region; contracted with a case's force at its node, the case's own response (linearity:
    both from the same factorisation, each refined to 1e-6)."""
    from data_spec.geometry import read_geometry
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    out = tmp_path / "d"
    shutil.copytree(reference, out)
    res = linear(TINY, out, "--synthetic", "3", "--green")
    assert res.returncode == 0, res.stderr
    lf = read_linear_fields(linear_fields_path(out))
    sh = read_shard(list_shards(out)[0])
    g = read_geometry(next((out / "geometry").glob("g*.h5")))
    np.testing.assert_array_equal(lf.green_nodes, np.setdiff1d(g.surface_nodes, sh.fixed_nodes))
    assert lf.green.shape == (lf.green_nodes.size, 3, lf.output_nodes.size, 3)
    for row in range(lf.case_index.size):
        at = np.searchsorted(lf.green_nodes, lf.load_nodes[row, 0])
        assert lf.green_nodes[at] == lf.load_nodes[row, 0]
        u = np.einsum("cnd,c->nd", lf.green[at].astype(np.float64), lf.forces[row, 0])
        np.testing.assert_allclose(u, lf.displacement[row], rtol=0,
                                   atol=1e-5 * np.abs(lf.displacement[row]).max())


def test_a_greens_function_near_a_point_is_the_whole_ones_rows_there(reference, tmp_path):
    """--green-near: the free surface nodes within --green-radius of the one nearest the
    point, each row the whole surface's (one factorisation, the same solves), the fixed
    region recorded; the nearest free node is computed, and so is its whole patch off the
    fixed region."""
    from data_spec.eligible_loads import grasp_patch
    from data_spec.geometry import read_geometry
    from data_spec.linear_fields import linear_fields_path, read_linear_fields

    whole, near = tmp_path / "whole", tmp_path / "near"
    for d in (whole, near):
        shutil.copytree(reference, d)
    g = read_geometry(next((whole / "geometry").glob("g*.h5")))
    sh = read_shard(list_shards(whole)[0])
    free = np.setdiff1d(g.surface_nodes, sh.fixed_nodes)
    c = free[np.argmax(g.points[free, 2])]
    point = g.points[c] + [0.5, 0.0, 1.0]   # off the mesh: its nearest free node is c
    radius = 0.3 * np.ptp(g.points, axis=0).max()
    assert linear(TINY, whole, "--green").returncode == 0
    res = linear(TINY, near, "--green", "--green-near", " ".join(map(repr, point)),
                 "--green-radius", str(radius))
    assert res.returncode == 0, res.stderr
    a, b = (read_linear_fields(linear_fields_path(d)) for d in (whole, near))
    want = free[np.linalg.norm(g.points[free] - g.points[c], axis=1) <= radius]
    np.testing.assert_array_equal(b.green_nodes, want)
    assert 0 < want.size < free.size and c in want
    patch = grasp_patch(g.points, g.surface_nodes, c, radius)
    assert set(np.intersect1d(patch, free)) <= set(want.tolist())
    np.testing.assert_allclose(b.green, a.green[np.searchsorted(a.green_nodes, want)],
                               rtol=0, atol=1e-6 * np.abs(a.green).max())
    np.testing.assert_array_equal(b.fixed_nodes, np.sort(sh.fixed_nodes))
    np.testing.assert_array_equal(a.fixed(g.surface_nodes), b.fixed(g.surface_nodes))
    for words in ("1 2", "1 2 x", "1 2 nan"):
        bad = linear(TINY, tmp_path / "x", "--green", "--green-near", words)
        assert bad.returncode == 2 and "--green-near" in bad.stderr, bad.stderr
        assert "Traceback" not in bad.stderr and not (tmp_path / "x").exists()


def test_a_greens_function_beyond_its_bound_is_refused_before_solving(reference, tmp_path,
                                                                     monkeypatch):
    from fem_sim.batch import linear as lin

    out = tmp_path / "d"
    shutil.copytree(reference, out)
    monkeypatch.setattr(lin, "GREEN_MAX_BYTES", 1000)
    with pytest.raises(ValueError, match=r"--green would hold .* unit responses"):
        lin.linear_fields(TINY, out, green=True)
    assert not (out / "linear.h5").exists()


def test_small_strain_responses_of_many_livers_are_refused(tmp_path):
    res = linear(ROOT / "data_spec" / "scenes" / "ci_scene4.toml", tmp_path / "d")
    assert res.returncode == 2
    assert "ci_scene4.toml" in res.stderr and "one liver" in res.stderr
