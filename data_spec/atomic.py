"""Atomic file creation: write under a temporary name in the same directory, then rename.

A reader (or a resumed batch) therefore sees either no file or a complete one, never a
half-written file, even if the writer is killed (SIGKILL) midway.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

TMP_MARK = ".tmp-"


@contextlib.contextmanager
def atomic_path(final: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``final``; rename it to ``final`` if the block succeeds."""
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = final.with_name(f"{final.name}{TMP_MARK}{os.getpid()}")
    try:
        yield tmp
        with open(tmp, "rb+") as fh:  # data on disk before the rename makes it visible
            os.fsync(fh.fileno())
        os.replace(tmp, final)
    finally:
        if tmp.exists():
            tmp.unlink()


def check_writable(directory: str | Path) -> None:
    """Create ``directory`` if needed and prove a file can be created in it; OSError naming
    the directory otherwise (read-only directory or file system, immutable attribute), so
    that a run fails before it spends any work, not at its first write.
    """
    d = Path(directory)
    probe = d / f".write-probe{TMP_MARK}{os.getpid()}"
    try:
        d.mkdir(parents=True, exist_ok=True)
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise OSError(f"{d}: cannot create files there ({exc.strerror or exc})") from None


def out_problem(path: str | Path, flag: str = "--out", directory: bool = False) -> str | None:
    """Why ``path`` cannot be written as a file (``directory``: made as a directory), None
    when it can: checked before any work and creating nothing (a probe file in the nearest
    existing ancestor, removed). The message names ``flag`` and what was expected.
    """
    path = Path(path)
    want = "a directory (created if missing)" if directory else "a file to write"
    if path.exists() and path.is_dir() != directory:
        return f"{flag} {path} is {'a file' if directory else 'a directory'}; expected {want}"
    parent = next(p for p in [path if directory else path.parent, *path.absolute().parents]
                  if p.exists())
    if not parent.is_dir():
        return f"{flag} {path}: {parent} is a file, not a directory; expected {want}"
    probe = parent / f".write-probe{TMP_MARK}{os.getpid()}"
    try:
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return f"{flag} {path}: cannot create files in {parent} ({exc.strerror or exc})"
    return None


def write_text_atomic(final: str | Path, text: str) -> None:
    with atomic_path(final) as tmp:
        tmp.write_text(text)


def leftover_temporaries(directory: str | Path) -> list[Path]:
    """Temporary files left by killed writers (safe to delete when no writer is running)."""
    return sorted(p for p in Path(directory).rglob(f"*{TMP_MARK}*") if p.is_file())
