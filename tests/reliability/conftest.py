"""Helpers of the reliability suite: a directory nobody may write to, even root."""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path

import pytest


@contextlib.contextmanager
def read_only(path: Path):
    """Make ``path`` unwritable for the duration: chmod for an ordinary user; for root, who
    ignores permissions, the immutable attribute (chattr +i). Skips when neither is possible
    here (root in a container without CAP_LINUX_IMMUTABLE)."""
    if os.geteuid() != 0:
        mode = path.stat().st_mode
        path.chmod(0o555)
        try:
            yield
        finally:
            path.chmod(mode)
        return
    if subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
        pytest.skip("root without chattr +i: no way to make a directory read-only here")
    try:
        yield
    finally:
        subprocess.run(["chattr", "-i", str(path)], check=True)
