"""The results ledger every resumable study keeps: one JSON record a line, appended as each
result comes, read back by its key so that a cut study skips what it has.

    runs = Ledger("bench/results/tradeoff_fem/runs.jsonl", key="key")
    for spec in plan:
        if key_of(spec) not in runs:
            runs.add(measure(spec))
    report(runs.records())        # {key: record}, the last record of a key winning

A key may be a field name or a function of the record (a tuple of fields, say). A line that
is not whole JSON (a study killed while writing it) is skipped with a warning naming the file
and the line, so the result is measured again rather than the study stopping.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Hashable, Iterator
from pathlib import Path


class Ledger:
    """A JSON-lines results file keyed by ``key`` (a field name or a function of a record)."""

    def __init__(self, path: str | Path, key: str | Callable[[dict], Hashable]):
        self.path = Path(path)
        self._key = (lambda r: r[key]) if isinstance(key, str) else key

    def key(self, record: dict) -> Hashable:
        return self._key(record)

    def __iter__(self) -> Iterator[dict]:
        if not self.path.exists():
            return
        for number, line in enumerate(self.path.read_text().splitlines(), 1):
            if not line.strip():
                continue
            try:
                yield json.loads(line)
            except json.JSONDecodeError:
                warnings.warn(f"{self.path}: line {number} is not whole JSON (a study cut "
                              "while writing it?); skipped, its result is measured again",
                              stacklevel=2)

    def records(self) -> dict:
        """Every record by its key; a key written twice keeps its last record."""
        return {self.key(r): r for r in self}

    def __contains__(self, key: Hashable) -> bool:
        return key in self.records()

    def add(self, record: dict) -> dict:
        """Append ``record`` (one line, flushed: a cut study keeps it) and return it."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a") as fh:
            fh.write(json.dumps(record, default=float) + "\n")
        return record
