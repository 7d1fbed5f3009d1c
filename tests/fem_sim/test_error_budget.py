"""The error budget's node errors (fem_sim.batch.knob_run.budget_case_errors) on hand-made
budget files: the reference's values at each budget mesh's vertices are found at the right
offset, and FE, surrogate and total errors are the distances between the three fields,
beyond the exclusion ball of the load and at every node."""

import numpy as np
import pytest

from fem_sim.batch import knob_run


def _write(case, degree, h, **arrays):
    np.savez(knob_run.budget_npz(case, degree, h), **arrays)


def test_budget_errors_take_the_reference_at_the_mesh_vertices(tmp_path, monkeypatch):
    monkeypatch.setattr(knob_run, "BUDGET_RESULTS", tmp_path)
    sizes = {m: i + 2 for i, m in enumerate(knob_run.BUDGET_MESHES)}   # 2, 3, 4, 5 vertices
    for (degree, h), n in sizes.items():
        nodes = np.c_[np.arange(n) * 10.0, np.zeros((n, 2))]   # x = 0, 10, 20, ... mm
        _write(0, degree, h, nodes=nodes, u_nodes=np.zeros((n, 3)))
    mesh = (1, 8.0)   # the third budget mesh: its reference values start after 2 + 3 rows
    assert knob_run.budget_reference_offsets(0)[mesh] == 5
    n = sizes[mesh]
    u_ref_here = np.tile([0.0, 0.0, -2.0], (n, 1))
    u_ref = np.concatenate([np.full((5, 3), 99.0), u_ref_here, np.full((5, 3), 99.0)])
    ref_nodes = np.array([[0.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    _write(0, *knob_run.BUDGET_REFERENCE, u=u_ref, nodes=ref_nodes,
           u_nodes=np.array([[0.0, 0.0, -4.0], [0.0, 0.0, 1.0]]))
    u_mesh = np.tile([0.0, 0.0, -1.5], (n, 1))          # the mesh 25 % too stiff
    _write(0, *mesh, nodes=np.c_[np.arange(n) * 10.0, np.zeros((n, 2))], u_nodes=u_mesh)
    fem = {(0, *knob_run.BUDGET_REFERENCE): {"status": "ok", "load_node": 1},
           (0, *mesh): {"status": "ok", "load_node": 2}}
    predicted = np.tile([0.0, 0.3, -1.5], (n, 1))       # the network 0.3 mm off its mesh
    e = knob_run.budget_case_errors(0, [0.0, 0.0, 0.0], *mesh, predicted, fem, exclude=15.0)
    # nodes at x = 0 and 10 mm are within 15 mm of the load: two of four remain
    assert e["fe"] == pytest.approx([0.5, 0.5]) and e["sur"] == pytest.approx([0.3, 0.3])
    assert e["tot"] == pytest.approx([np.hypot(0.5, 0.3)] * 2)
    assert e["fe_all"].shape == (4,) and e["scale"] == pytest.approx(4.0)
    assert e["offset"] == pytest.approx(10.0)   # loaded vertex x = 20 against x = 30
    row = knob_run.budget_summary([e, e])
    assert (row["cases"], row["fe"], row["surrogate"]) == (2, pytest.approx(0.5),
                                                           pytest.approx(0.3))
    assert row["u_ref_max"] == pytest.approx(4.0) and row["offset"] == pytest.approx(10.0)
    # every node: x = 0 and 10 mm too, where the mesh is off the reference by the same 0.5
    assert row["fe_all"] == pytest.approx(0.5)
    assert row["total_p95"] == pytest.approx(np.hypot(0.5, 0.3))
    fem[(0, *mesh)]["status"] = "failed"
    assert knob_run.budget_case_errors(0, [0, 0, 0], *mesh, predicted, fem, 15.0) is None
