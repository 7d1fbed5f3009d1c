"""Scene schema: shipped scenes load, malformed scenes are rejected with every problem listed."""

import copy
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from data_spec import SceneError, load_scene, parse_scene, write_geometry
from tests.fixtures import box_mesh

SCENES = sorted((Path(__file__).parents[2] / "data_spec" / "scenes").glob("*.toml"))


def minimal() -> dict:
    return {"scene": {"name": "t", "n_simulations": 2},
            "geometry": {"source": "phantom"},
            "loads": {"magnitude": 0.4}}


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_shipped_scenes_are_valid(path):
    scene = load_scene(path)
    assert scene.name == tomllib.loads(path.read_text())["scene"]["name"]
    fr = scene.load_fractions
    assert fr[-1] == 1.0 and all(a < b for a, b in zip(fr, fr[1:]))


def test_paper_scene_sizes_and_what_varies():
    by_name = {p.stem: load_scene(p) for p in SCENES}
    sizes = {k: v.n_simulations for k, v in by_name.items() if k.startswith("scene")}
    assert sizes == {"scene1_base": 400, "scene2_two_forces": 1500,
                     "scene3_materials": 3000, "scene4_livers": 1015,
                     "scene4_phantoms": 10200, "scene4_grasp": 725}
    assert by_name["scene1_base"].varies == {"loads": True, "material": False,
                                             "geometry": False}
    assert by_name["scene2_two_forces"]["loads"]["count"] == 2
    assert by_name["scene3_materials"].varies["material"]
    assert by_name["scene4_livers"].varies["geometry"]
    assert by_name["scene4_phantoms"].varies["geometry"]
    # the grasp scene: the same livers, the same validation livers set aside, tools not forces
    grasp, forces = by_name["scene4_grasp"], by_name["scene4_livers"]
    for key in ("livers", "validation", "exclude", "mesh_size", "population_seed"):
        assert grasp["geometry"][key] == forces["geometry"][key], key
    assert grasp["fixed"] == forces["fixed"] and grasp["solver"] == forces["solver"]
    assert grasp["loads"]["kind"] == "grasp" and grasp["loads"]["magnitude"] == 40.0
    assert grasp["loads"]["min_distance_to_fixed"] > grasp["loads"]["patch_radius"]


def test_defaults_filled_and_hash_stable():
    a = parse_scene(minimal())
    assert a["material"]["c"] == [4.1e-3] and a["material"]["K_over_mu"] == 200.0
    assert a.load_fractions == [(i + 1) / 10 for i in range(10)]
    assert a["solver"]["quadrature_degree"] == 1
    b = parse_scene(copy.deepcopy(minimal()))
    assert a.hash == b.hash
    raw = minimal()
    raw["loads"]["magnitude"] = 0.5
    assert parse_scene(raw).hash != a.hash


def test_malformed_scene_lists_every_problem(tmp_path):
    geo = box_mesh(2)  # 27 nodes
    write_geometry(tmp_path / "liver.h5", geo)
    text = """
[scene]
name = "bad"
n_simulations = "many"
colour = "red"

[geometry]
source = "file"
path = "liver.h5"

[fixed]
kind = "nodes"
nodes = [%s]

[loads]
magnitude = -0.4
""".replace("%s", ", ".join(str(i) for i in range(30)))
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    problems = err.value.problems
    msg = str(err.value)
    assert str(path) in msg
    assert any("scene.colour: unknown key" in p for p in problems)
    assert any(p.startswith("scene.n_simulations: expected an integer in [1, 10000000], "
                            "got 'many'")
               for p in problems)
    assert any(p.startswith("loads.magnitude: expected a number > 0") and "-0.4" in p
               for p in problems)
    # 30 ids but the mesh has 27 nodes: both the count and the out-of-range ids are named.
    assert any("fixed.nodes: 30 ids given but the mesh has only 27 nodes" in p for p in problems)
    assert any("fixed.nodes: node ids [27, 28, 29] are out of range" in p for p in problems)
    assert len(problems) == 5, problems


@pytest.mark.parametrize("mutate, expected", [
    (lambda r: r.update(extra={}), "extra: unknown top-level key"),
    (lambda r: r["loads"].update(kind="patch"), "loads.patch_radius: missing"),
    (lambda r: r["loads"].update(magnitude=[0.5, 0.1]), "loads.magnitude: expected"),
    (lambda r: r["geometry"].update(source="file"), "geometry.path: missing"),
    (lambda r: r["geometry"].update(variety="anatomical"),
     "geometry.variety: only used when source = 'population'"),
    (lambda r: r["geometry"].update(source="population", population_size=4, pca_components=2,
                                    variety="wide"), "geometry.variety: expected one of"),
    (lambda r: r.update(material={"c": [1e-3, 2e-3], "m": [3.0]}),
     "material: c and m must have one entry per Ogden term"),
    (lambda r: r.update(material={"K": 1.0, "K_over_mu": 3.0}), "give K or K_over_mu"),
    (lambda r: r.update(steps={"fractions": [0.5, 0.2, 1.0]}), "steps.fractions: expected"),
    (lambda r: r.update(fixed={"kind": "sphere", "radius": 3.0}), "fixed.center: missing"),
    (lambda r: r.update(fixed={"kind": "points", "points": [[0, 0, 0]]}),
     "fixed.radius: missing"),
    (lambda r: r.update(fixed={"kind": "points", "points": [[0, 0]], "radius": 2.0}),
     "fixed.points: expected a non-empty list of points"),
    (lambda r: r.update(solver={"degree": 3}), "solver.degree: expected an integer in [1, 2]"),
    (lambda r: r.update(solver={"element": "ut4"}), "solver.element: expected one of"),
    (lambda r: r.update(solver={"element": "anp", "degree": 2}),
     "solver.element = 'anp', degree = 2"),
    (lambda r: r.update(loads={"magnitude": float("nan")}), "loads.magnitude: expected"),
    (lambda r: r.update(cases=[{"load_nodes": [1, 2], "forces": [[0, 0, 1]]}]),
     "cases[0]: 2 load_nodes but 1 forces"),
    (lambda r: r.update(material={"sample": {"kind": "uniform", "c": [[1e-3, 2e-3]]}}),
     "material.sample.m: missing"),
])
def test_single_problem_is_named(mutate, expected):
    raw = minimal()
    mutate(raw)
    with pytest.raises(SceneError) as err:
        parse_scene(raw, "x.toml")
    assert any(expected in p for p in err.value.problems), err.value.problems


def test_explicit_cases_set_simulation_count():
    raw = minimal()
    del raw["scene"]["n_simulations"]
    raw["cases"] = [{"load_nodes": [5], "forces": [[0.0, 0.0, -0.4]]},
                    {"load_nodes": [7], "forces": [[0.4, 0.0, 0.0]],
                     "material": {"c": [3e-3], "m": [8.0], "K_over_mu": 100.0}}]
    scene = parse_scene(raw)
    assert scene.n_simulations == 2
    assert scene.varies["material"]
    with pytest.raises(SceneError, match="out of range"):
        scene.check_mesh(6)
    scene.check_mesh(8)


def test_unreadable_and_invalid_toml(tmp_path):
    with pytest.raises(SceneError, match="cannot read the file"):
        load_scene(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[scene\nname=")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(bad)


def test_box_mesh_is_exact():
    g = box_mesh(3, (2.0, 1.0, 1.0))
    p, c = g.points, g.cells
    vol = np.linalg.det(p[c[:, 1:]] - p[c[:, :1]]) / 6
    assert vol.min() > 0 and np.isclose(vol.sum(), 2.0)
    t = g.surface_triangles  # outward: divergence theorem gives the volume back
    assert np.isclose(np.einsum("ij,ij->", p[t[:, 0]], np.cross(p[t[:, 1]], p[t[:, 2]])) / 6,
                      2.0)


def test_every_schema_key_is_documented():
    from data_spec.scene import schema_table

    readme = (Path(__file__).parents[2] / "data_spec" / "README.md").read_text()
    missing = [k for k, _, _ in schema_table() if f"`{k}`" not in readme]
    assert missing == []


def test_absurd_simulation_count_is_refused():
    """n_simulations = 1e12 would plan for minutes before anything is said."""
    raw = tomllib.loads((Path(__file__).parents[2] / "data_spec" / "scenes" /
                         "tiny_scene1.toml").read_text())
    raw["scene"]["n_simulations"] = 10**12
    with pytest.raises(SceneError, match=r"scene.n_simulations: expected an integer in "
                                         r"\[1, 10000000\]"):
        parse_scene(raw)


def test_non_utf8_scene_file_is_named(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes("[scene]\nname = \"f\u00e9e\"\n".encode("latin-1"))
    with pytest.raises(SceneError, match=r"(?s)latin1.toml.*not UTF-8 text"):
        load_scene(path)


def test_solver_settings_outside_their_bounds_are_refused():
    """first_increment is a fraction of the first load step: (0, 1]."""
    from data_spec.solver_settings import SolverSettings

    assert SolverSettings.from_dict({"first_increment": 1.0}).first_increment == 1.0
    for v, bound in ((0.0, "> 0.0"), (1.5, "<= 1.0")):
        with pytest.raises(ValueError, match=f"settings.first_increment: expected a number.*"
                                             f"{re.escape(bound)}.*got {v}"):
            SolverSettings.from_dict({"first_increment": v})


def test_the_datasets_copy_of_a_scene_with_a_relative_mesh_path_reads_the_same_scene(tmp_path):
    from data_spec.scene import dataset_copy_text

    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "liver.vtk").write_text("not read: only its existence is checked")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    scene = scenes / "s.toml"
    scene.write_text('schema_version = 1\n[scene]\nname = "s"\nn_simulations = 2\n'
                     '[geometry]\nsource = "file"\npath = \'../meshes/liver.vtk\'  # relative\n'
                     'mesh_size = 9.0\n[fixed]\nkind = "sphere"\ncenter = [0, 0, 0]\n'
                     'radius = 5.0\n[loads]\nmagnitude = 0.4\n')
    original = load_scene(scene)
    kept = tmp_path / "dataset" / "scene.toml"
    kept.parent.mkdir()
    kept.write_text(dataset_copy_text(scene))
    again = load_scene(kept)  # a verbatim copy would look for dataset/../meshes/liver.vtk
    assert again.hash == original.hash
    assert again["geometry"]["path"] == str((tmp_path / "meshes" / "liver.vtk").resolve())
    assert "# relative" in kept.read_text()  # the rest of the file is kept as written


def test_a_mesh_path_through_a_linked_folder_is_made_absolute_one_way(tmp_path):
    """The scene, its dataset copy and a relocated copy make a relative path absolute by one
    rule (a linked folder kept as written, as CI links ../shared): the same hash all three."""
    from data_spec.scene import absolute_path, dataset_copy_text
    from data_spec.scene_writer import relocated_scene, scene_toml

    (tmp_path / "real").mkdir()
    (tmp_path / "real" / "liver.vtk").write_text("not read: only its existence is checked")
    (tmp_path / "project").mkdir()
    (tmp_path / "project" / "shared").symlink_to(tmp_path / "real")
    scene = tmp_path / "project" / "s.toml"
    scene.write_text('schema_version = 1\n[scene]\nname = "s"\nn_simulations = 2\n'
                     '[geometry]\nsource = "file"\npath = "shared/liver.vtk"\n'
                     'mesh_size = 9.0\n[fixed]\nkind = "sphere"\ncenter = [0, 0, 0]\n'
                     'radius = 5.0\n[loads]\nmagnitude = 0.4\n')
    original = load_scene(scene)
    linked = str(tmp_path.resolve() / "project" / "shared" / "liver.vtk")
    assert original["geometry"]["path"] == linked == absolute_path(scene.parent,
                                                                   "shared/liver.vtk")
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / "scene.toml").write_text(dataset_copy_text(scene))
    (tmp_path / "moved.toml").write_text(scene_toml(relocated_scene(scene)))
    for other in (tmp_path / "copy" / "scene.toml", tmp_path / "moved.toml"):
        assert load_scene(other).hash == original.hash


def test_a_relocated_scene_written_elsewhere_is_the_same_scene_at_its_new_size(tmp_path):
    """A study's copy of the shipped real-liver scene (another directory, another size) reads
    the same livers: only n_simulations differs, which the dataset's growth accepts."""
    from data_spec.scene_writer import relocated_scene, scene_toml

    shipped = SCENES[0].parent / "scene4_livers.toml"
    d = relocated_scene(shipped)
    assert Path(d["geometry"]["livers"]).is_absolute()
    n = d["scene"]["n_simulations"] + 1015
    d["scene"]["n_simulations"] = n
    moved = tmp_path / "elsewhere" / "scene.toml"
    moved.parent.mkdir()
    moved.write_text(scene_toml(d))
    a, b = load_scene(shipped), load_scene(moved)
    assert b.n_simulations == n and a.hash != b.hash
    assert b.hash_at(a.n_simulations) == a.hash


def test_solver_combinations_come_from_one_table():
    """The scene check and the solver ask data_spec.solver_rules: every unsupported
    combination is refused naming its keys; 'mumps' says its new name."""
    from data_spec import solver_rules

    tiny = tomllib.loads((SCENES[0].parent / "tiny_scene1.toml").read_text())

    def check(**solver):
        raw = copy.deepcopy(tiny)
        raw["solver"] = {"degree": 1, **solver}
        try:
            parse_scene(raw, "s.toml")
        except SceneError as exc:
            return str(exc)
        return ""

    assert check() == ""
    assert check(element="anp", linear_solver="direct") == ""
    for bad in ({"element": "anp", "linear_solver": "gamg"},
                {"element": "anp", "factorization": "petsc"},
                {"linear_solver": "gamg", "factorization": "pardiso"},
                {"degree": 2, "element": "anp"}):
        msg = check(**bad)
        assert "not a supported combination" in msg, (bad, msg)
        for k, v in bad.items():
            assert f"{k} = {v!r}" in msg, (k, msg)
    assert "'mumps' is now 'direct'" in check(linear_solver="mumps")
    # the solver's path for valid combinations, by rank count
    assert solver_rules.linear_path("direct", "auto", {}, 1) == "serial"
    assert solver_rules.linear_path("direct", "auto", {}, 4) == "petsc"
    assert solver_rules.linear_path("direct", "auto", {"pc_type": "lu"}, 1) == "petsc"
    assert solver_rules.linear_path("gamg", "auto", {}, 2) == "gamg"
    with pytest.raises(ValueError, match="on 2 ranks per simulation"):
        solver_rules.linear_path("direct", "pardiso", {}, 2)
    assert solver_rules.problems("anp", 1, 1, "direct", "auto", {}, ranks=2)
    assert not solver_rules.problems("anp", 1, 1, "direct", "auto", {}, ranks=1)


def test_loads_near_a_site_are_drawn_within_its_reach_only():
    """[loads] near: the eligible nodes are the rule's own within near_radius (default 20 mm)
    of the site, the fixed ones and those too near the fixed region still left out; a site
    off the liver leaves none; a bad site is refused by the schema, naming the key."""
    from data_spec.eligible_loads import eligible_load_nodes
    from data_spec.geometry import box_mesh as box

    g = box(10, (100.0, 100.0, 10.0))
    fixed = g.surface_nodes[g.points[g.surface_nodes, 0] == 0.0]
    rule = {"eligible": "surface", "min_distance_to_fixed": 30.0}
    every = eligible_load_nodes(rule, g.points, g.surface_nodes, fixed)
    site = [50.0, 50.0, 10.0]
    for reach, near in ((20.0, {"near": site}), (35.0, {"near": site, "near_radius": 35.0})):
        got = eligible_load_nodes({**rule, **near}, g.points, g.surface_nodes, fixed)
        d = np.linalg.norm(g.points[every] - site, axis=1)
        assert np.array_equal(got, every[d <= reach]) and 0 < got.size < every.size
    far = eligible_load_nodes({**rule, "near": [500.0, 0, 0]}, g.points, g.surface_nodes, fixed)
    assert far.size == 0
    raw = tomllib.loads((Path(__file__).parents[2] / "data_spec" / "scenes" /
                         "tiny_scene1.toml").read_text())
    raw["loads"]["near"] = [1.0, 2.0]
    with pytest.raises(SceneError, match=r"loads.near: expected a list of 3 finite numbers"):
        parse_scene(raw)
