"""The variables of ``make patient`` and ``make liver`` checked before any work (the set-up,
meshing and FE steps take minutes; a bad K or AT must not be found by the last step).

    python3 scripts/make_args.py patient LIVER=... MODEL=... K=40 HELD=0 ...
    python3 scripts/make_args.py liver LIVER=... MODEL=... AT="X Y Z FX FY FZ" ...

Exit 2 with one line per problem, naming the variable, its value and what was expected;
standard library only (it runs before the environments exist).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

USAGE = {
    "patient": 'make patient LIVER=file MODEL=run [K=40] [HELD=0] [PSCENE=scene] '
               '[LOAD=grasp] [PATIENT=dir]',
    "liver": 'make liver LIVER=file [MODEL=run] (AT="X Y Z FX FY FZ" | GRASP="X Y Z DX DY DZ") '
             '[PSCENE=scene] [FRAME=...] [LIVER_DIR=dir]',
}
FRAMES = ("", "population", "LPS", "RAS", "auto")


def _whole(value: str, what: str) -> str | None:
    return None if value.isdigit() else f"expected a whole number >= 0 ({what})"


def _one_of(*options: str):
    def check(value: str) -> str | None:
        return None if value in options else "expected one of " + ", ".join(
            repr(o) for o in options)
    return check


def _file(value: str) -> str | None:
    if not value:
        return "missing: give the liver's surface file"
    return None if Path(value).is_file() else "no such file"


def _model(value: str) -> str | None:
    if not value:
        return "missing: give a trained run (its model/model.json)"
    return None if (Path(value) / "model" / "model.json").is_file() else \
        "not a trained run: no model/model.json in it (surrogate train writes one)"


def _scene(value: str) -> str | None:
    return None if Path(value).is_file() else "no such scene file"


def _at(value: str, unit: str = "a force in N (FX FY FZ)") -> str | None:
    words = value.split()
    try:
        numbers = [float(w) for w in words]
    except ValueError:
        numbers = []
    if len(words) != 6 or len(numbers) != 6 or not all(map(math.isfinite, numbers)):
        return ("expected six finite numbers: a point on the liver's surface in mm (X Y Z) "
                f"and {unit}")
    return None


def _site(value: str) -> str | None:
    words = value.split()
    try:
        ok = not words or (len(words) == 3 and all(math.isfinite(float(w)) for w in words))
    except ValueError:
        ok = False
    return None if ok else "expected three finite numbers: a point near the liver (X Y Z, mm)"


def _grasp(value: str) -> str | None:
    return _at(value, "the grasped patch's displacement in mm (DX DY DZ)")


CHECKS = {
    "patient": {"LIVER": _file, "MODEL": _model, "PSCENE": _scene,
                "K": lambda v: _whole(v, "the FE simulations the model adapts on"),
                "HELD": lambda v: _whole(v, "FE simulations kept out, to measure on"),
                "SYNTHETIC": lambda v: _whole(v, "drawn small-strain loads"),
                "ORDER": _one_of("1", "2"), "GREEN": _one_of("0", "1"),
                "FRAME": _one_of(*FRAMES), "LOAD": _one_of("", "force", "grasp"), "SITE": _site},
    "liver": {"LIVER": _file, "MODEL": _model, "PSCENE": _scene, "AT": _at, "GRASP": _grasp,
              "FRAME": _one_of(*FRAMES)},
}
# variables of which exactly one is given: the checks above see only the one given
ONE_OF = {"liver": ("AT", "GRASP")}


def problems(target: str, values: dict[str, str]) -> list[str]:
    """One line per variable of ``target`` that is wrong (empty when all are right)."""
    out = []
    pick = ONE_OF.get(target, ())
    given = [n for n in pick if values.get(n, "").strip()]
    if pick and len(given) != 1:
        out.append(f"make {target}: give one of " + " or ".join(pick) + (
            f", not {len(given)}" if given else ""))
    for name, check in CHECKS[target].items():
        value = values.get(name, "").strip()
        if name in pick and not value:   # said above when none is given
            continue
        why = check(value)
        if why:
            out.append(f"make {target}: {name}={value!r}: {why}")
    if target == "patient" and not any("MODEL=" in line for line in out):
        out += _model_load(values.get("MODEL", ""), values.get("LOAD", "").strip() or "force")
    return out


def _model_load(model: str, load: str) -> list[str]:
    """A model of the other load than LOAD (its model.json says which it learned)."""
    import json

    learned = json.loads((Path(model) / "model" / "model.json").read_text()).get("load", "nodal")
    if (load == "grasp") == (learned == "grasp"):
        return []
    return [f"make patient: MODEL={model!r} learned {'grasps' if learned == 'grasp' else 'forces'}"
            f", LOAD={load!r} adapts a model of {'grasps' if load == 'grasp' else 'forces'}: "
            "give LOAD=grasp with a model of grasps (the default, models/scene4_grasp)"]


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in CHECKS:
        print(f"usage: make_args.py {{{','.join(CHECKS)}}} NAME=VALUE ...", file=sys.stderr)
        return 2
    values = dict(a.split("=", 1) for a in argv[1:] if "=" in a)
    found = problems(argv[0], values)
    for line in found:
        print(line, file=sys.stderr)
    if found:
        print(f"usage: {USAGE[argv[0]]}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
