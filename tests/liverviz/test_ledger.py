"""The results ledger of the resumable studies (liverviz.ledger): what is added is read back by
its key, the last record of a key wins, and a line cut by a killed study is skipped, named."""

import json

import pytest

from liverviz.ledger import Ledger


def test_records_come_back_by_key_and_the_last_of_a_key_wins(tmp_path):
    runs = Ledger(tmp_path / "sub" / "runs.jsonl", key="id")
    assert runs.records() == {} and "a" not in runs  # no file yet: nothing done
    runs.add({"id": "a", "seconds": 1.5})
    runs.add({"id": "b", "seconds": 2.0})
    runs.add({"id": "a", "seconds": 3.0})
    assert runs.records() == {"a": {"id": "a", "seconds": 3.0}, "b": {"id": "b", "seconds": 2.0}}
    assert "b" in runs and "c" not in runs
    # one line a record, appended: a second ledger on the file sees the same
    lines = (tmp_path / "sub" / "runs.jsonl").read_text().splitlines()
    assert [json.loads(x)["seconds"] for x in lines] == [1.5, 2.0, 3.0]
    assert Ledger(runs.path, key="id").records() == runs.records()


def test_a_key_may_be_a_function_of_the_record(tmp_path):
    fem = Ledger(tmp_path / "fem.jsonl", key=lambda r: (r["case"], r["degree"], r["h"]))
    fem.add({"case": 0, "degree": 2, "h": 16.0, "status": "ok"})
    assert (0, 2, 16.0) in fem and (0, 1, 16.0) not in fem


def test_a_cut_line_is_skipped_with_a_warning_naming_the_file_and_line(tmp_path):
    path = tmp_path / "runs.jsonl"
    path.write_text('{"id": "a", "v": 1}\n{"id": "b", "v"\n')
    runs = Ledger(path, key="id")
    with pytest.warns(UserWarning, match=r"runs\.jsonl: line 2 is not whole JSON"):
        assert runs.records() == {"a": {"id": "a", "v": 1}}
