"""A solver process driven by another.

``python -m fem_sim serve`` reads one command a line on its standard input (a JSON list, the
words of a ``python -m fem_sim`` command line), runs it in the same process and writes one
JSON line on its standard output::

    ["mesh", "liver.obj", "--scene", "scene.toml", "--out", "mesh.h5", "--no-picture"]
    -> {"rc": 0, "seconds": 3.1}

Whatever the commands print goes to the standard error, so that the standard output holds
the answers only. Between two commands the process imports the solver's modules (dolfinx,
PETSc, the forms) once: a trainer process that meshes a liver, registers a model on it
while this process waits, and then asks for its Green's function (``make liver``, driven by
:mod:`surrogate.make_liver`) pays the solver's start once and while it works on its side.
Two words beyond fem_sim's commands keep a liver factorised between lines, for the
manipulator (:mod:`fem_sim.batch.green_live`): ``green-open DATA`` and ``green-rows OUT.npy
NODE ...``; ``prepare MESH SCENE`` builds a meshed liver's problem for a later ``linear`` on
it (make liver has it built while the model is registered). A line that is not a list of
words is answered ``{"rc": 2, "error": ...}``; the process ends with its standard input.
"""

from __future__ import annotations

import json
import os
import sys
import time


def _answer_stream():
    """The standard output kept for the answers; file descriptor 1 then writes to the
    standard error (the commands' prints, PETSc's and the compilers' included).
    """
    sys.stdout.flush()
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return answers


def _warm() -> None:
    """Import what a solve needs (seconds of a first import) while the caller works."""
    import fem_sim.batch.linear  # noqa: F401
    import fem_sim.solver.problem  # noqa: F401


_LIVE: list = [None]   # the liver green-open keeps (fem_sim.batch.green_live)


def _prepare(words: list[str]) -> int:
    """``prepare MESH SCENE``: the liver problem of a meshed liver built now, for a later
    ``linear`` of a scene on that mesh (:func:`fem_sim.batch.linear.prepare`).
    """
    if len(words) != 3:
        print(f"fem_sim serve: expected prepare MESH SCENE, got {words}", file=sys.stderr)
        return 2
    from fem_sim.batch.linear import prepare

    try:
        prepare(words[1], words[2])
    except (ValueError, OSError, KeyError) as exc:
        print(f"fem_sim serve: prepare: {exc}", file=sys.stderr)
        return 2
    return 0


def _run(words, main) -> dict:
    if not (isinstance(words, list) and words and all(isinstance(w, str) for w in words)):
        return {"rc": 2, "error": f"expected a JSON list of words, got {words!r}"}
    if words[0] == "serve":
        return {"rc": 2, "error": "serve runs commands, not itself"}
    t = time.perf_counter()
    try:
        if words[0] in ("green-open", "green-rows"):
            from fem_sim.batch.green_live import serve_verb

            _LIVE[0], rc = serve_verb(_LIVE[0], words)
        elif words[0] == "prepare":
            rc = _prepare(words)
        else:
            rc = main(words)
    except SystemExit as exc:   # argparse's usage errors
        rc = exc.code if isinstance(exc.code, int) else 2
    return {"rc": int(rc or 0), "seconds": round(time.perf_counter() - t, 3)}


def serve(main, stdin=None) -> int:
    """Answer the lines of ``stdin`` (the standard input), each a command of ``main`` (fem_sim's
    command line, which passes itself) or a green-open / green-rows line.
    """
    answers, warmed = _answer_stream(), False
    for line in stdin or sys.stdin:
        if not line.strip():
            continue
        try:
            words = json.loads(line)
        except json.JSONDecodeError as exc:
            out = {"rc": 2, "error": f"not JSON: {exc}"}
        else:
            out = _run(words, main)
        sys.stderr.flush()
        answers.write(json.dumps(out) + "\n")
        if not warmed:
            _warm()
            warmed = True
    return 0
