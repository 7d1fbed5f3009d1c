"""Reading an exported model's files back, checked (:mod:`surrogate.export` writes them):
model.json's format, version and design, and the network's parameters against the config.
Plain files only: JSON, and .npz read with allow_pickle=False.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from flax import traverse_util

MODEL_FORMAT = "liverfem-surrogate"
MODEL_VERSION = 3          # 3: explicit layer names; 2: the design is recorded
READABLE_VERSIONS = (1, 2, 3)  # 1-2: flax's automatic names Dense_i; version 1 is node-wise


FINGERPRINT = "fingerprint.json"


def _sha256(path: Path) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def write_fingerprint(directory: str | Path) -> Path:
    """The SHA-256 of every file of the model directory, in ``fingerprint.json``: what a
    shipped model carries so that :func:`check_fingerprint` (and so ``load_predictor``)
    refuses a file changed or lost since it was measured.
    """
    d = Path(directory)
    (d / FINGERPRINT).write_text(json.dumps({"sha256": _hashes(d)}, indent=1) + "\n")
    return d / FINGERPRINT


def _hashes(d: Path) -> dict:
    """{name: SHA-256} of every file of the model directory ``d`` but its fingerprint."""
    return {f.name: _sha256(f) for f in sorted(d.iterdir())
            if f.is_file() and f.name != FINGERPRINT}


def model_digest(directory: str | Path) -> str:
    """16 hex digits of the SHA-256 of every file of the model directory (its fingerprint
    aside): what a result fitted against the model (a patient's corrections) records of it.
    """
    import hashlib

    text = "".join(f"{name} {h}\n" for name, h in _hashes(Path(directory)).items())
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def check_fingerprint(directory: str | Path) -> None:
    """ValueError naming the file when a model directory with a ``fingerprint.json`` holds
    a file changed, lost or added since it was written; nothing for a directory without one
    (a model trained here).
    """
    d = Path(directory)
    path = d / FINGERPRINT
    if not path.exists():
        return
    try:
        files = json.loads(path.read_text())["sha256"]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a model fingerprint ({exc})") from None
    here = {f.name for f in d.iterdir() if f.is_file() and f.name != FINGERPRINT}
    for name in sorted(here | set(files)):
        if name not in files or name not in here or _sha256(d / name) != files[name]:
            what = "added" if name not in files else "missing" if name not in here else \
                "changed"
            raise ValueError(f"{d / name}: {what} since the model was fingerprinted "
                             f"({path}): not the model its card measured; fetch it again")


def read_meta(path: Path, designs) -> dict:
    """model.json, checked: the format, a readable version and one of ``designs``' names."""
    try:
        meta = json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: missing (not a model directory?)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: expected a JSON object, got {type(meta).__name__}")
    if meta.get("format") != MODEL_FORMAT:
        raise ValueError(f"{path}: not a {MODEL_FORMAT} model")
    if meta.get("version") not in READABLE_VERSIONS:
        raise ValueError(f"{path}: version {meta.get('version')!r}, this code reads "
                         f"{', '.join(map(str, READABLE_VERSIONS))}")
    design = meta.setdefault("design", "nodewise")
    if design not in designs:
        raise ValueError(f"{path}: design {design!r}, expected one of "
                         f"{', '.join(designs)}")
    return meta


def layer_names(n_hidden: int, last: str) -> list[str]:
    return [f"hidden_{i}" for i in range(n_hidden)] + [last]


def read_params(path: Path, dim: int, hidden: tuple[int, ...], out: int = 3,
                 version: int = MODEL_VERSION, last: str = "output", members: int = 1) -> dict:
    """The network's parameters, checked against the architecture in the config: every layer
    present with the right shapes, every value finite; an ensemble's arrays carry its
    ``members`` along a leading axis. Models before version 3 name their layers Dense_0,
    Dense_1, ... in order; they are read under the explicit names.
    """
    try:
        with np.load(path, allow_pickle=False) as z:
            flat = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise ValueError(f"{path}: missing") from None
    except (OSError, ValueError) as exc:  # truncated, not an npz, or a pickled array
        raise ValueError(f"{path}: cannot be read without executing code ({exc})") from None
    names = layer_names(len(hidden), last)
    if version < 3:
        old = {f"Dense_{i}": n for i, n in enumerate(names)}
        flat = {f"{old.get(k.split('/')[0], k.split('/')[0])}/{k.split('/', 1)[-1]}": v
                for k, v in flat.items()}
    widths = (dim, *hidden, out)
    want = {}
    lead = (members,) if members > 1 else ()
    for i, name in enumerate(names):
        want[f"{name}/kernel"] = (*lead, widths[i], widths[i + 1])
        want[f"{name}/bias"] = (*lead, widths[i + 1])
    problems = [f"'{k}' has shape {flat[k].shape}, the config says {shape}"
                for k, shape in want.items() if k in flat and flat[k].shape != shape]
    problems += [f"'{k}' is missing" for k in want if k not in flat]
    problems += [f"'{k}' is not part of the network" for k in flat if k not in want]
    problems += [f"'{k}' contains NaN or inf" for k in want
                 if k in flat and not np.all(np.isfinite(flat[k]))]
    if problems:
        raise ValueError(f"{path}: " + "; ".join(problems))
    return traverse_util.unflatten_dict(flat, sep="/")
