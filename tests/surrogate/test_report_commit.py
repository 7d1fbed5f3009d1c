"""The commit a benchmark report names (liverviz.report.commit): "+ local changes" for code
that differs from HEAD, not for the reports the run itself writes under docs/."""

import subprocess

from liverviz import report


def test_only_changes_outside_docs_mark_the_commit(tmp_path, monkeypatch):
    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args],
                       cwd=tmp_path, check=True, capture_output=True)

    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "table.md").write_text("old\n")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("init", "-q")
    git("add", ".")
    git("commit", "-qm", "first")
    monkeypatch.setattr(report, "ROOT", tmp_path)
    sha = report.commit()
    assert len(sha) >= 7 and "local changes" not in sha
    (tmp_path / "docs" / "table.md").write_text("new\n")  # a report rewritten by the run
    (tmp_path / "notes.txt").write_text("untracked\n")
    assert report.commit() == sha
    (tmp_path / "code.py").write_text("x = 2\n")
    assert report.commit() == sha + " + local changes"
