"""A dataset grown by raising its scene's ``n_simulations`` and editing nothing else.

A simulation's draws depend on the scene's seed and its own index only, so the shards of the
same scene at a smaller size are still its simulations: ``generate`` keeps them and makes
only the new ones (it refuses to shrink a dataset). They carry the hash of the scene at the
size they were made at (:meth:`data_spec.scene.Scene.hash_at`); the dataset directory records
those sizes (``scene_sizes.json``) so that the generator and the validator accept their
shards, and only theirs: a scene edited in any other way is another scene.
"""

from __future__ import annotations

import json
from pathlib import Path

SIZES = "scene_sizes.json"


def earlier_sizes(directory: str | Path) -> list[int]:
    """The sizes the dataset's scene had before (empty for a dataset never resized)."""
    path = Path(directory) / SIZES
    if not path.exists():
        return []
    sizes = json.loads(path.read_text())
    if not (isinstance(sizes, list) and all(isinstance(n, int) and n > 0 for n in sizes)):
        raise ValueError(f"{path}: expected a list of simulation counts > 0, got {sizes!r}")
    return sizes


def record_size(directory: str | Path, n: int) -> None:
    """Add size ``n`` to the dataset's earlier sizes (written whole, then renamed)."""
    from data_spec.atomic import atomic_path

    sizes = sorted(set(earlier_sizes(directory)) | {int(n)})
    with atomic_path(Path(directory) / SIZES) as tmp:
        tmp.write_text(json.dumps(sizes), encoding="utf-8")


def same_but_size(scene, other) -> bool:
    """Whether ``other`` is ``scene`` at another size (every other key the same)."""
    return scene.hash_at(other.n_simulations) == other.hash


def accepted_hashes(scene, directory: str | Path) -> set[str]:
    """The scene hashes a shard of ``scene`` in ``directory`` may carry: the scene's own and
    its hash at each earlier size of the dataset.
    """
    return {scene.hash} | {scene.hash_at(n) for n in earlier_sizes(directory)}
