"""The manual cannot rot: every link, repository path, make target, command, subcommand and
flag that README.md (and docs/README.md) names exists."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[2]
TOP = ("data_spec/", "fem_sim/", "surrogate/", "liverviz/", "tests/", "bench/", "docs/",
       "docker/", "requirements/", "scripts/")
MODULE_FILES = {"fem_sim": "fem_sim/__main__.py", "surrogate": "surrogate/__main__.py",
                "data_spec": "data_spec/__main__.py", "surrogate.viewer": "surrogate/viewer.py"}


def make_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text()
    return set(re.findall(r"^([A-Za-z][\w-]*):", text, flags=re.M))


def code_lines(text: str) -> list[str]:
    """Lines of fenced code blocks, continuation lines (ending in a backslash) joined."""
    out, block = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            block = not block
            continue
        if block:
            if out and out[-1].endswith("\\"):
                out[-1] = out[-1][:-1] + " " + line.strip()
            else:
                out.append(line)
    return out


def problems(text: str, root: Path = ROOT, base: Path = ROOT) -> list[str]:
    found = []
    for target in re.findall(r"\]\(([^)#\s]+)", text):
        if "://" not in target and not (base / target).exists():
            found.append(f"link {target}: no such file")
    for path in re.findall(r"`([A-Za-z_./-]+)`", text):
        if path.startswith(TOP) and "*" not in path and not (root / path).exists():
            found.append(f"path {path}: no such file")
    targets = make_targets()
    for t in re.findall(r"\bmake ([a-z][\w-]*)", text):
        if t not in targets:
            found.append(f"make {t}: no such target")
    for line in code_lines(text):
        m = re.search(r"-m ([\w.]+)(?: ([a-z][\w-]*))?", line)
        script = re.search(r"python (bench/\w+\.py|scripts/\w+\.py)", line)
        if m and m.group(1) in MODULE_FILES:
            src = (root / MODULE_FILES[m.group(1)]).read_text()
            sub = m.group(2)
            if sub and "add_parser(" in src and f'add_parser("{sub}"' not in src:
                found.append(f"python -m {m.group(1)} {sub}: no such subcommand")
            flags = re.findall(r"(?<![\w-])(--[a-z][\w-]*)", line[m.end():])
        elif script:
            if not (root / script.group(1)).exists():
                found.append(f"{script.group(1)}: no such script")
                continue
            src = (root / script.group(1)).read_text()
            flags = re.findall(r"(?<![\w-])(--[a-z][\w-]*)", line[script.end():])
        else:
            continue
        for flag in flags:
            if f'"{flag}"' not in src:
                found.append(f"{line.strip()[:60]}...: flag {flag} unknown")
    return found


def test_the_checker_finds_what_has_rotted():
    bad = ("see [the report](docs/no_such.md) and `fem_sim/no_such.py`; run `make no-such`.\n"
           "```sh\n.venv-solver/bin/python -m fem_sim generate s.toml --out d \\\n"
           "    --no-such-flag\n.venv-solver/bin/python -m fem_sim frobnicate x\n```\n")
    found = problems(bad)
    assert any("docs/no_such.md" in p for p in found)
    assert any("fem_sim/no_such.py" in p for p in found)
    assert any("make no-such" in p for p in found)
    assert any("--no-such-flag" in p for p in found)
    assert any("frobnicate" in p for p in found)
    assert problems("```sh\npython -m fem_sim generate s.toml --out d --only 0..3\n```\n") == []


@pytest.mark.parametrize("doc", ["README.md", "docs/README.md", "data_spec/README.md"])
def test_documented_commands_targets_flags_and_links_exist(doc):
    path = ROOT / doc
    assert problems(path.read_text(), base=path.parent) == []


def test_readme_is_a_manual_of_a_few_hundred_lines():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 450, len(lines)


def test_no_text_dates_itself_to_a_period_of_work():
    """The project speaks of itself in the present: no 'session N' in the tracked text."""
    pattern = re.compile(r"\bsessions? \d+|\bsession-\d+|\buntil session\b", re.I)
    hits = []
    for f in ROOT.rglob("*"):
        if (f.suffix in (".py", ".md", ".toml", ".sh", ".c", ".txt") or f.name == "Makefile") \
                and not any(p.startswith(".") or p in ("runs", "build") or p.endswith(".egg-info")
                            for p in
                            f.relative_to(ROOT).parts) and f.is_file() \
                and f != Path(__file__):
            for i, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
                if pattern.search(line):
                    hits.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()[:80]}")
    assert hits == []
