"""Build and cache the small C extensions of fem_sim with cffi (at first use, per machine).

Extensions are cached under ``$FEM_SIM_CACHE`` (default ``$XDG_CACHE_HOME/fem_sim`` or
``~/.cache/fem_sim``), keyed by a hash of the C source, the declarations, the build flags and
the interpreter. Every rank may build at once: each builds in its own temporary directory and
renames atomically. :func:`load` returns None (and logs a warning naming the fallback) when
the extension cannot be built, so callers can fall back to a slower path.
"""

from __future__ import annotations

import hashlib
import importlib.util
import logging
import os
import sys
import sysconfig
import tempfile
from pathlib import Path

log = logging.getLogger(__name__)

_loaded: dict[str, object] = {}
_errors: dict[str, str] = {}  # why a module could not be built


def cache_dir() -> Path:
    if os.environ.get("FEM_SIM_CACHE"):
        return Path(os.environ["FEM_SIM_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "fem_sim"


def _build(name: str, source: str, cdef: str, target: Path, **build) -> None:
    import cffi

    ffi = cffi.FFI()
    ffi.cdef(cdef)
    ffi.set_source(name, source, **build)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        built = ffi.compile(tmpdir=tmp, verbose=False)
        os.replace(built, target)


def load(stem: str, source_file: Path, cdef: str, fallback: str, **build):
    """The compiled module ``stem`` (with ``.ffi`` and ``.lib``) or None if it cannot be built.

    ``build`` goes to ``cffi.FFI.set_source`` (extra_compile_args, libraries, include_dirs,
    ...); ``fallback`` names what callers do instead, for the warning.
    """
    if stem in _loaded:
        return _loaded[stem]
    source = source_file.read_text()
    key = hashlib.sha256((source + cdef + repr(sorted(build.items())) + sys.version)
                         .encode()).hexdigest()[:16]
    name = f"_fem_sim_{stem}_{key}"
    target = cache_dir() / (name + sysconfig.get_config_var("EXT_SUFFIX"))
    mod = None
    try:
        if not target.exists():
            _build(name, source, cdef, target, **build)
        spec = importlib.util.spec_from_file_location(name, target)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except Exception as exc:  # no compiler, missing headers, read-only cache, ...
        mod = None
        _errors[stem] = f"{type(exc).__name__}: {exc}"
        log.warning("fem_sim: compiled %s unavailable (%s); %s", stem, exc, fallback)
    _loaded[stem] = mod
    return mod


def why_unavailable(stem: str) -> str | None:
    """Why :func:`load` returned None for ``stem`` (None if it loaded or was never tried)."""
    return _errors.get(stem)
