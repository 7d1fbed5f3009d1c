"""A population of liver files: real CT livers registered from the template without a folded
tetrahedron, fixed where the template's vena-cava region lands, and a three-liver population
generated end to end (../shared/data/livers/real)."""

from pathlib import Path

import numpy as np
import pytest

from data_spec.geometry import region_area, signed_volumes
from fem_sim.batch.chunked import mpirun_env

MPI_ENV = mpirun_env()
REAL = Path(__file__).parents[3] / "shared" / "data" / "livers" / "real"
needs_livers = pytest.mark.skipif(not REAL.exists(), reason="shared/data/livers/real not present")


def population_scene(path: Path, livers: str, sims: int, steps: int, pca: int,
                     extra: str = "") -> Path:
    """A three-liver file population at 20 mm, P1, written to ``path``."""
    path.write_text(f'''schema_version = 1
[scene]
name = "{path.stem}"
n_simulations = {sims}
seed = 4
[geometry]
source = "population"
livers = "{livers}"
population_size = 3
{extra}
frame = "population"
pca_components = {pca}
mesh_size = 20.0
[loads]
magnitude = 0.4
min_distance_to_fixed = 20.0
[steps]
n = {steps}
[solver]
degree = 1
''')
    return path


@pytest.fixture(scope="module")
def registrar():
    from fem_sim.geometry.file_population import Registrar
    from fem_sim.geometry.phantom import make_phantom

    return Registrar(make_phantom(1000, 16.0, "anatomical"), "vena_cava", "population")


@needs_livers
@pytest.mark.parametrize("name", ["Amos-004", "LiTS-1"])
def test_the_template_reaches_a_real_liver_without_folding(registrar, name):
    """Both livers fold the template under the plain surface registration (CPD, harmonic
    interior: 193 and about 100 of 3,419 tetrahedra inverted); the registration folds none,
    stays within 3 mm of the liver's surface, and fixes the liver over a patch at least half
    the template's, on its surface."""
    from fem_sim.geometry.file_population import prepare
    from liverreg.cpd import cpd_nonrigid, surface_samples

    liver, reg, rec = prepare(REAL / f"{name}.obj", registrar, 16.0)
    T = registrar.template
    assert rec.inverted == 0 and reg.inverted == 0
    assert np.all(signed_volumes(reg.points, T.cells) > 0)
    assert rec.min_jacobian == pytest.approx(reg.min_jacobian) and reg.min_jacobian > 0
    assert reg.residual < 3.0
    fixed = liver.regions["vena_cava"]
    assert np.isin(fixed, liver.surface_nodes).all()
    area = region_area(liver.points, liver.surface_triangles, fixed)
    assert area == pytest.approx(rec.fixed_area) and area >= 0.5 * registrar.area
    # the plain registration of the same liver does fold: the test can fail
    plain = registrar.morph.move(cpd_nonrigid(surface_samples(liver, 600), registrar.samples)
                                 .transform(T.points[T.surface_nodes]))
    assert registrar.morph.inverted(plain) > 0


def test_unfolding_undoes_a_fold_made_by_hand(registrar):
    """A surface node pushed through the liver folds its cells; the relaxation restores a
    valid mesh while leaving the nodes far from the fold where they were asked to go."""
    m = registrar.morph
    S = m.points[m.boundary].copy()
    target = S + np.array([1.0, -2.0, 0.5])  # a translation: nothing folds
    moved, rounds = m.unfold(target)
    assert rounds == 0 and np.allclose(moved[m.boundary], target)
    k = int(np.argmax(S[:, 2]))  # the top node, pushed through the liver and out below it
    for depth in (80.0, S[k, 2] - S[:, 2].min() + 10.0):
        target[k] = S[k] + np.array([1.0, -2.0, 0.5 - depth])
        assert m.inverted(m.move(target)) > 0
        moved, rounds = m.unfold(target)
        assert m.inverted(moved) == 0 and m.min_jacobian(moved) > 0
        far = np.linalg.norm(S - S[k], axis=1) > 60.0
        assert np.allclose(moved[m.boundary][far], target[far], atol=1e-6)


@needs_livers
@pytest.mark.mpi
def test_a_three_liver_file_population_generates_end_to_end(tmp_path):
    """Three real livers (a fourth set aside for validation): meshed and registered by two
    ranks, each its share, fixed, their shape coefficients from the PCA with the phantom
    template kept apart, simulated; a second run reuses everything; one rank alone makes the
    same meshes, registrations and shape coefficients."""
    import json
    import subprocess
    import sys

    from data_spec import read_geometry
    from data_spec.validate import validate_dataset

    scene = population_scene(tmp_path / "real3.toml", f"{REAL}/LiTS-1*.obj", sims=6, steps=2,
                             pca=2, extra='validation = ["LiTS-10"]')
    out = tmp_path / "data"

    def generate(ranks=1, to=out):  # a process per run: a run holds its directory's lock
        return subprocess.run(["mpirun", "-n", str(ranks), sys.executable, "-m", "fem_sim",
                               "generate", str(scene), "--out", str(to), "--no-progress"],
                              capture_output=True, text=True, env=MPI_ENV)

    first = generate(ranks=2)  # each rank meshes and registers its share of the livers
    assert first.returncode == 0, first.stderr[-2000:]
    assert "liver files prepared per rank: [2, 1]" in first.stdout, first.stdout
    assert not (out / "geometry" / "staged").exists()
    records = json.loads((out / "geometry" / "livers.json").read_text())
    names = [p.stem for p in sorted(REAL.glob("LiTS-1*.obj")) if p.stem != "LiTS-10"][:3]
    assert [r["name"] for r in records] == names
    assert all(r["inverted"] == 0 and r["min_jacobian"] > 0 for r in records)
    with np.load(out / "geometry" / "population.npz") as z:
        assert z["geometry_ids"].size == 3 and "template_points" in z.files
        assert z["coefficients"].shape == (3, 3) and np.all(z["inverted"] == 0)
    geos = [read_geometry(p) for p in sorted((out / "geometry").glob("g*.h5"))]
    assert len(geos) == 3 and all(g.shape_coefficients.shape == (2,) for g in geos)
    assert validate_dataset(out) == []
    before = (out / "geometry" / "meshes.json").read_text()
    again = generate()
    assert again.returncode == 0 and "6 skipped" in again.stdout, again.stderr[-2000:]
    assert (out / "geometry" / "meshes.json").read_text() == before
    one = generate(ranks=1, to=tmp_path / "one_rank")  # the livers all prepared on rank 0
    assert one.returncode == 0 and "prepared per rank" not in one.stdout, one.stderr[-2000:]
    assert (tmp_path / "one_rank" / "geometry" / "meshes.json").read_text() == before
    assert json.loads((tmp_path / "one_rank" / "geometry" / "livers.json").read_text())[0][
        "residual"] == pytest.approx(records[0]["residual"], rel=1e-9)
    with np.load(out / "geometry" / "population.npz") as a, \
            np.load(tmp_path / "one_rank" / "geometry" / "population.npz") as b:
        assert np.allclose(a["coefficients"], b["coefficients"], atol=1e-6)


def test_livers_prepared_by_other_code_are_announced(caplog):
    """A dataset whose index holds a liver file's mesh under another key (other code or
    settings) warns that the liver is prepared, hence simulated, again; a liver the dataset
    never held, a phantom and a liver whose key matches say nothing."""
    from types import SimpleNamespace as NS

    from fem_sim.geometry.file_population import _warn_stale

    members = [NS(name="A", path=Path("/x/A.obj")), NS(name="B", path=Path("/x/B.obj")),
               NS(name="phantom 3", path=None)]
    keys = ["file A.obj 11, code new", "file B.obj 22, code new", "phantom 3"]
    _warn_stale("DATA", {"file A.obj 11, code old": "g1", keys[1]: "g2"}, members, keys)
    assert "DATA: 1 of the 3 livers were prepared by other code or settings (A)" in caplog.text
    caplog.clear()
    _warn_stale("DATA", {keys[1]: "g2", "phantom 3 old": "g3"}, members, keys)
    assert caplog.text == ""


@needs_livers
@pytest.mark.mpi
def test_a_broken_liver_file_in_another_ranks_share_is_named_and_no_rank_hangs(tmp_path):
    """A population whose second file is not a liver: rank 1, whose share it is, leaves it
    to rank 0, which names the file and the way to leave it out; every rank ends, nothing is
    simulated."""
    import shutil
    import subprocess
    import sys

    livers = tmp_path / "livers"
    livers.mkdir()
    shutil.copy(REAL / "LiTS-1.obj", livers / "a.obj")
    (livers / "b.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")  # one triangle
    shutil.copy(REAL / "LiTS-11.obj", livers / "c.obj")
    scene = population_scene(tmp_path / "s.toml", f"{livers}/*.obj", sims=3, steps=1, pca=1)
    res = subprocess.run(["mpirun", "-n", "2", sys.executable, "-m", "fem_sim", "generate",
                          str(scene), "--out", str(tmp_path / "d"), "--no-progress"],
                         capture_output=True, text=True, env=MPI_ENV, timeout=300)
    assert res.returncode == 2, res.stderr[-2000:]
    assert "b.obj" in res.stderr and "geometry.exclude" in res.stderr, res.stderr[-2000:]
    assert not list((tmp_path / "d").glob("sims/sim_*.h5"))
