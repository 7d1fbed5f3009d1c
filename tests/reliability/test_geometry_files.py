"""A dataset's geometry files are checked by ``validate``: orientation and integrity (item 6:
a geometry whose cells all have negative volume was accepted and validated)."""

from __future__ import annotations

import h5py
import numpy as np

from data_spec import validate_dataset
from data_spec.geometry import read_geometry
from tests.fixtures import synthetic_dataset


def _geometry_file(d):
    (path,) = sorted((d / "geometry").glob("*.h5"))
    return path


def test_a_clean_dataset_validates(tmp_path):
    synthetic_dataset(tmp_path, n_sims=2, n=3)
    assert validate_dataset(tmp_path) == []


def test_inverted_cells_are_reported_even_with_a_consistent_hash(tmp_path):
    """Swapping two nodes of every cell inverts it (volume -> -volume). The hash is rewritten
    to match, so only the orientation check can catch it."""
    synthetic_dataset(tmp_path, n_sims=2, n=3)
    path = _geometry_file(tmp_path)
    g = read_geometry(path)
    g.cells = g.cells[:, [0, 2, 1, 3]]
    with h5py.File(path, "r+") as f:
        f["cells"][...] = g.cells
        f.attrs["content_hash"] = g.content_hash
    problems = validate_dataset(tmp_path)
    assert problems and all(str(path) in p for p in problems)
    n = g.cells.shape[0]
    assert any(f"{n} of {n} have a volume <= 0" in p for p in problems), problems


def test_an_edited_point_breaks_the_content_hash(tmp_path):
    synthetic_dataset(tmp_path, n_sims=2, n=3)
    path = _geometry_file(tmp_path)
    with h5py.File(path, "r+") as f:
        p = f["points"][...]
        p[5, 0] = np.nextafter(p[5, 0], np.inf)  # one ulp: still a valid mesh
        f["points"][...] = p
    problems = validate_dataset(tmp_path)
    assert any("differ from the stored content hash" in p for p in problems), problems
