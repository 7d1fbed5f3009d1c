"""Dataset views: a dataset directory made of links to another's files, nothing copied.

A view is a valid dataset for every reader (the trainer, the validator, ``fem_sim generate``):
``first(data, n)`` holds the first ``n`` simulations of ``data``; ``without(data, ids, view)``
its simulations less those on the livers ``ids``; ``extension(data, n, out)`` starts a larger
dataset of the same scene from ``data``'s shards, so that ``generate`` goes on past them
without touching ``data``.
"""

from __future__ import annotations

import os
from pathlib import Path


def shard_count(data: str | Path) -> int:
    """The number of shard files (``sims/sim_*.h5``) of a dataset directory."""
    return len(list((Path(data) / "sims").glob("sim_*.h5")))


def dataset_fingerprint(data: str | Path, sims=None) -> str:
    """A digest of which simulations a dataset directory holds: each shard's name and the
    checksum it carries (a dataset made again, with the same count of shards on other meshes,
    has another fingerprint); ``sims``: of those simulations' shards only.
    """
    import hashlib

    import h5py

    from data_spec.shards import list_shards

    h = hashlib.sha256()
    want = None if sims is None else {int(i) for i in sims}
    for shard in list_shards(data):
        if want is not None and int(shard.stem.split("_")[1]) not in want:
            continue
        try:
            with h5py.File(shard, "r") as f:
                mark = str(f.attrs.get("checksum", ""))
        except OSError:  # not a readable shard: what it is on disk
            mark = f"unreadable {shard.stat().st_size}"
        h.update(f"{shard.name} {mark}\n".encode())
    return h.hexdigest()[:16]


def link_shards(data: Path, view: Path, n: int, shards=None) -> None:
    """Symbolic links in ``view/sims`` to the first ``n`` shards of ``data`` (or to
    ``shards``, paths of its shards) with their XDMF files (a shard without its XDMF is not a
    valid one).
    """
    (view / "sims").mkdir(parents=True, exist_ok=True)
    if shards is None:
        shards = sorted((data / "sims").glob("sim_*.h5"))[:n]
    for shard in shards:
        for p in (data / "sims").glob(Path(shard).stem + ".*"):
            if not (view / "sims" / p.name).exists():
                (view / "sims" / p.name).symlink_to(p.resolve())


def _link_scene(data: Path, view: Path) -> None:
    """Links in ``view`` to ``data``'s scene copy and liver files, and to its livers'
    small-strain responses when it has them (``fem_sim linear --population``: rows of
    simulations the view leaves out are never read).
    """
    view.mkdir(parents=True, exist_ok=True)
    for name in ("scene.toml", "geometry", "linear"):
        if name == "linear" and not (data / name).is_dir():
            continue
        if not (view / name).exists():
            (view / name).symlink_to((data / name).resolve())


def first(data: str | Path, n: int, view: str | Path | None = None) -> Path:
    """A view of the first ``n`` simulations of ``data`` (``data`` itself when it holds no
    more); by default ``data/../first_N``.
    """
    data = Path(data)
    if n >= shard_count(data):
        return data
    view = Path(view) if view is not None else data.parent / f"first_{n}"
    _link_scene(data, view)
    link_shards(data, view, n)
    return view


def without(data: str | Path, geometry_ids, view: str | Path) -> Path:
    """A view of ``data``'s simulations less those on the livers ``geometry_ids`` (its scene
    and liver files as they are: a population's registration keeps every liver's shape); an
    earlier view in ``view`` of other livers is brought to these. ValueError for an id no
    simulation of ``data`` is on.
    """
    from data_spec.shards import list_shards, read_shard

    data, view, drop = Path(data), Path(view), set(geometry_ids)
    kept, seen = [], set()
    for shard in list_shards(data):
        gid = read_shard(shard).geometry_id
        seen.add(gid)
        if gid not in drop:
            kept.append(shard)
    if drop - seen:
        raise ValueError(f"{data}: no simulation on the livers {sorted(drop - seen)}")
    _link_scene(data, view)
    stems = {shard.stem for shard in kept}
    for p in (view / "sims").glob("sim_*.*") if (view / "sims").exists() else ():
        if p.is_symlink() and p.name.split(".")[0] not in stems:
            p.unlink()   # a link of an earlier view of other livers
    link_shards(data, view, len(kept), kept)
    return view


def extension(data: str | Path, n: int, out: str | Path) -> Path:
    """A dataset directory ``out`` that starts from ``data``'s first ``n`` shards (with their
    XDMF files), its liver files and its scene copy, hard-linked or linked, for ``generate``
    to go on from: the new shards land in ``out`` only.
    """
    data, out = Path(data), Path(out)
    (out / "geometry").mkdir(parents=True, exist_ok=True)
    for p in sorted((data / "geometry").iterdir()):
        if not (out / "geometry" / p.name).exists():
            os.link(p, out / "geometry" / p.name)  # generate reads them as its own
    if not (out / "scene.toml").exists():
        os.link(data / "scene.toml", out / "scene.toml")
    link_shards(data, out, n)
    return out
