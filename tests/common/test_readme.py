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


def _link_and_path_problems(text: str, root: Path, base: Path) -> list[str]:
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
    return found


def _command_problems(line: str, root: Path) -> list[str]:
    """A code line's ``python -m MODULE SUB --flags`` or ``python SCRIPT --flags``: the
    subcommand and every flag exist in the source that parses them."""
    m = re.search(r"-m ([\w.]+)(?: ([a-z][\w-]*))?", line)
    script = re.search(r"python ((?:bench|scripts|demos)/\w+\.py)", line)
    found = []
    if m and m.group(1) in MODULE_FILES:
        src = (root / MODULE_FILES[m.group(1)]).read_text()
        sub = m.group(2)
        if sub and "add_parser(" in src and f'add_parser("{sub}"' not in src:
            found.append(f"python -m {m.group(1)} {sub}: no such subcommand")
        flags = re.findall(r"(?<![\w-])(--[a-z][\w-]*)", line[m.end():])
    elif script:
        if not (root / script.group(1)).exists():
            return [f"{script.group(1)}: no such script"]
        src = (root / script.group(1)).read_text()
        flags = re.findall(r"(?<![\w-])(--[a-z][\w-]*)", line[script.end():])
    else:
        return []
    return found + [f"{line.strip()[:60]}...: flag {flag} unknown" for flag in flags
                    if f'"{flag}"' not in src]


def problems(text: str, root: Path = ROOT, base: Path = ROOT) -> list[str]:
    found = _link_and_path_problems(text, root, base)
    for line in code_lines(text):
        found += _command_problems(line, root)
    return found


NUMBER = re.compile(r"(?<![\w.])\d[\d,]*(?:\.\d+)?")


def figure_problems(text: str, base: Path = ROOT) -> list[str]:
    """Every number a Results row quotes must be in one of the reports the row links (so the
    manual cannot drift from the reports), and every row must link one."""
    found = []
    section = text.split("\n## Results", 1)[-1] if "\n## Results" in text else ""
    for row in section.splitlines():
        cells = [c.strip() for c in row.strip().strip("|").split("|")]
        if len(cells) < 3 or set(cells[0]) <= {"-"} or cells[0] == "what":
            continue
        links = re.findall(r"\]\(([^)#\s]+\.md)\)", cells[-1])
        if not links:
            found.append(f"{cells[0][:50]}: no report linked")
            continue
        reports = " ".join((base / link).read_text().replace(",", "") for link in links)
        for number in NUMBER.findall(cells[1]):
            if number.replace(",", "") not in reports:
                found.append(f"{cells[0][:50]}: {number} is in none of {links}")
    return found


def paragraph_problems(text: str, longest: int = 12) -> list[str]:
    """Prose paragraphs and list items (outside code blocks and tables) of more than
    ``longest`` lines."""
    found, para, block = [], [], False
    for line in text.splitlines() + [""]:
        if line.startswith("```"):
            block = not block
            continue
        if block or line.startswith("|"):
            continue
        if para and (not line.strip() or line.startswith("- ")):  # a list item is its own
            if len(para) > longest:
                found.append(f"a paragraph of {len(para)} lines: {para[0][:60]}")
            para = []
        if line.strip():
            para.append(line)
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


def test_the_readme_is_a_manual():
    """At most 3,000 words, no paragraph over 12 lines, lines of a reader's width."""
    text = (ROOT / "README.md").read_text()
    assert len(text.split()) <= 3000, len(text.split())
    assert paragraph_problems(text) == []
    long = [line[:40] for line in text.splitlines() if len(line) > 110 and "|" not in line
            and not line.startswith("![")]
    assert long == []


def test_the_readmes_figures_are_the_reports():
    assert figure_problems((ROOT / "README.md").read_text()) == []


def test_the_figure_and_paragraph_checks_find_drift():
    report = ROOT / "docs" / "demo.md"
    table = ("\n## Results\n\n| what | figure | report |\n|---|---|---|\n"
             "| the demo | skill 0.9999 | [docs/demo.md](docs/demo.md) |\n"
             "| unlinked | 1.0 | none |\n")
    found = figure_problems(table)
    assert any("0.9999 is in none of" in p for p in found), found
    assert any("no report linked" in p for p in found), found
    skill = re.search(r"skill = MEE_NN / MEE_naive = ([\d.]+)", report.read_text()).group(1)
    assert figure_problems(table.replace("0.9999", skill).split("| unlinked")[0]) == []
    assert paragraph_problems("\n".join(["words"] * 13)) != []
    assert paragraph_problems("\n".join(["words"] * 12)) == []


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
