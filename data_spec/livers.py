"""The livers of a population scene, by name: phantoms (``population_seed`` onward) and liver
files (``livers``: a folder or a glob), less the validation livers the scene sets aside and
the livers it excludes (``exclude``: for example one the repair refuses).

A population scene's members, in order: ``phantoms`` phantoms (seeds ``population_seed``,
``population_seed + 1``, ...), then the liver files sorted by name, the validation livers
left out, the first ``population_size`` of them when that is given. Without ``livers`` the
population is ``population_size`` phantoms, as before. The template every liver is registered
from is the phantom of seed ``population_seed`` (the first member when the scene has phantoms):
its vena-cava region is where each liver file gets its fixed region.

numpy-free: the trainer (validation livers, truth scenes) and the solver read the same list.
"""

from __future__ import annotations

import functools
import glob
from dataclasses import dataclass
from pathlib import Path

LIVER_SUFFIXES = (".obj", ".stl", ".ply", ".vtp", ".vtk", ".off")


@dataclass(frozen=True)
class Member:
    """One liver of a population: a phantom (``seed``) or a file (``path``)."""

    seed: int | None = None
    path: str | None = None

    @property
    def name(self) -> str:
        return Path(self.path).stem if self.path else f"phantom-{self.seed}"


def liver_folder_files(pattern: str) -> list[Path]:
    """The liver surface files a ``livers`` value names: every file with a surface suffix in a
    folder, or the files a glob matches, sorted by name.
    """
    p = Path(pattern)
    if p.is_dir():
        found = [f for f in p.iterdir() if f.suffix.lower() in LIVER_SUFFIXES]
    else:
        found = [Path(f) for f in glob.glob(pattern)]
    return sorted(f for f in found if f.is_file())


def file_problems(g: dict) -> list[str]:
    """What is wrong with a population's files (empty: nothing), for the scene's checks."""
    if "livers" not in g:
        return [f"geometry.validation: {g['validation']!r} but no geometry.livers to set "
                "them aside from"] if g.get("validation") else []
    files = liver_folder_files(g["livers"])
    if not files:
        return [f"geometry.livers: {g['livers']!r} names no liver file (expected a folder or "
                f"a glob of surface files: {', '.join(LIVER_SUFFIXES)})"]
    names = {f.stem for f in files}
    unknown = [v for v in g.get("validation", []) + g.get("exclude", []) if v not in names]
    problems = []
    if unknown:
        problems.append(f"geometry.validation/exclude: {', '.join(unknown[:5])} not among the "
                        f"{len(files)} livers of {g['livers']!r} (expected file names without "
                        "their suffix)")
    if len(set(g.get("validation", []))) != len(g.get("validation", [])):
        problems.append("geometry.validation: a liver is named twice")
    return problems


def training_files(g: dict) -> list[Path]:
    """The liver files of the population (validation livers left out)."""
    if "livers" not in g:
        return []
    held = set(g.get("validation", [])) | set(g.get("exclude", []))
    files = [f for f in liver_folder_files(g["livers"]) if f.stem not in held]
    cap = g.get("population_size")
    return files[:cap] if cap is not None else files


def validation_files(g: dict) -> list[Path]:
    """The validation livers' files, in the scene's order."""
    if "livers" not in g:
        return []
    by_name = {f.stem: f for f in liver_folder_files(g["livers"])}
    return [by_name[v] for v in g.get("validation", []) if v in by_name]


def population_count(g: dict) -> int:
    """How many livers a population scene's ``[geometry]`` holds (the folder read once per
    distinct setting).
    """
    return _count(g.get("livers"), tuple(g.get("validation", [])), tuple(g.get("exclude", [])),
                  g.get("phantoms", 0), g.get("population_size"), g.get("population_seed", 0))


@functools.lru_cache(maxsize=16)
def _count(livers, validation, exclude, phantoms, size, seed) -> int:
    return len(members({"livers": livers, "validation": list(validation),
                        "exclude": list(exclude), "phantoms": phantoms,
                        "population_size": size, "population_seed": seed}
                       if livers is not None else {"population_size": size}))


def members(g: dict) -> list[Member]:
    """Every liver of a population scene's ``[geometry]``, in the population's order."""
    seed = g.get("population_seed", 0)
    if "livers" not in g:
        return [Member(seed=seed + i) for i in range(g["population_size"])]
    return [Member(seed=seed + i) for i in range(g.get("phantoms", 0))] + \
        [Member(path=str(f)) for f in training_files(g)]
