"""Dataset summary: counts, displacement statistics and solver statistics of a directory."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from data_spec import geometry_path, list_shards, read_geometry, read_shard, validate_dataset


def _statistics(paths) -> dict:
    """Counts, failure reasons, maximum displacements, Newton iterations, cut-backs and
    seconds of the readable shards.
    """
    st = {"ok": 0, "failed": 0, "reasons": {}, "max_disp": [], "iters": [], "cut": [],
          "wall": [], "candidates": []}
    for p in paths:
        try:
            s = read_shard(p)
        except (OSError, KeyError, ValueError):
            continue
        if s.status == "ok":
            st["ok"] += 1
        else:
            st["failed"] += 1
            key = s.failure_reason.split(";")[0][:80]
            st["reasons"][key] = st["reasons"].get(key, 0) + 1
        if s.n_done:
            st["max_disp"].append(np.linalg.norm(s.displacement[-1], axis=1).max())
            if s.status == "ok" and s.output_nodes.size:
                st["candidates"].append((st["max_disp"][-1], p))
            st["iters"].extend(s.stats.newton_iterations.tolist())
            st["cut"].extend(s.stats.cutbacks.tolist())
        st["wall"].append(float(s.stats.info.get("total_wall_time", np.sum(s.stats.wall_time))))
    return st


def _picture(directory: Path, shown, png) -> Path:
    """The shown simulations' deformed livers at full load, side by side."""
    from fem_sim.render import render_shards

    items = []
    for what, p in shown:
        s = read_shard(p)
        g = read_geometry(geometry_path(directory, s.geometry_id))
        u = np.zeros((g.n_nodes, 3))
        u[s.output_nodes] = s.displacement[-1]
        items.append((g, u, s.load_nodes, s.forces, s.fixed_nodes,
                      f"{what}: sim {s.sim_index}, force "
                      f"{np.linalg.norm(s.forces, axis=1).max():.2f} N\nmax displacement "
                      f"{np.linalg.norm(u, axis=1).max():.1f} mm"))
    png = Path(png or directory / "summary.png")
    png.parent.mkdir(parents=True, exist_ok=True)
    return render_shards(items, png, f"{directory}: deformed livers at full load (largest, "
                         "median, smallest maximum displacement)")


def summary(directory: str | Path, out=sys.stdout, png: str | Path | None = None) -> int:
    """Print counts and statistics; render three deformed livers to ``png`` (default
    DIR/summary.png): the converged simulations with the largest, the median and the smallest
    maximum displacement, so the picture shows the dataset's range.
    """
    directory = Path(directory)
    paths = list_shards(directory)
    if not paths:
        print(f"{directory}: no shards", file=sys.stderr)
        return 1
    problems = validate_dataset(directory)
    st = _statistics(paths)
    pr = lambda *a: print(*a, file=out)  # noqa: E731
    pr(f"dataset {directory}: {len(paths)} shards, {st['ok']} ok, {st['failed']} failed, "
       f"{len(problems)} validation problem(s)")
    if st["max_disp"]:
        d = np.array(st["max_disp"])
        pr(f"  max |u| at full load, mm: median {np.median(d):.2f}, min {d.min():.2f}, "
           f"max {d.max():.2f}")
    if st["iters"]:
        pr(f"  Newton iterations per load step: mean {np.mean(st['iters']):.2f}, max "
           f"{max(st['iters'])}; cut-backs: {int(np.sum(st['cut']))}")
    if st["wall"]:
        pr(f"  seconds per simulation: median {np.median(st['wall']):.2f}, total "
           f"{np.sum(st['wall']):.0f}")
    for k, v in sorted(st["reasons"].items(), key=lambda kv: -kv[1]):
        pr(f"  failed x{v}: {k}")
    for p in problems[:20]:
        pr(f"  problem: {p}")
    shown = range_cases(st["candidates"])
    if shown:
        pr(f"  picture: {_picture(directory, shown, png)}")
    return 0 if not problems else 1


def range_cases(candidates) -> list[tuple[str, Path]]:
    """(label, shard) of the largest, median and smallest of (max |u|, shard) pairs; fewer
    when there are fewer distinct shards.
    """
    if not candidates:
        return []
    order = sorted(candidates, key=lambda c: (c[0], str(c[1])))
    picks = [("largest", order[-1]), ("median", order[(len(order) - 1) // 2]),
             ("smallest", order[0])]
    seen, out = set(), []
    for what, (_, p) in picks:
        if p not in seen:
            seen.add(p)
            out.append((what, p))
    return out
