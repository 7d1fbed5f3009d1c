"""The index in README.md names real tests: a renamed or deleted test breaks it here."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).parents[2]


def test_every_test_named_in_the_index_exists():
    text = (Path(__file__).parent / "README.md").read_text()
    named = re.findall(r"`(tests/[\w/]+\.py)::(\w+)`", text)
    assert len(named) >= 25
    rows = re.findall(r"^\| (\d+) \|", text, flags=re.M)
    assert rows == [str(i) for i in range(1, 14)]  # the findings of issues 15, 52, 53, 81
    missing = [f"{path}::{name}" for path, name in named
               if not re.search(rf"^def {name}\(", (ROOT / path).read_text(), flags=re.M)]
    assert missing == []
