"""Ogden point kernel: the compiled C kernel (fem_sim.material.ogden_c) against the numpy
reference, stress and stress + tangent, at 75k points (the 15k-node liver's at P1): medians of
--runs calls, their ratios and the kernels' largest relative difference.

    OPENBLAS_NUM_THREADS=1 .venv-solver/bin/python bench/bench_kernel.py [--points 75000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from fem_sim.material.ogden import OgdenMaterial, ogden_point_kernel, point_kernel


def median_time(fn, runs: int) -> float:
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--points", type=int, default=75_000)
    ap.add_argument("--runs", type=int, default=7)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    F = np.eye(3) + 0.15 * rng.standard_normal((a.points, 3, 3))
    mat = OgdenMaterial((4.1e-3,), (10.06,), 100 * 4.1e-3)
    print(f"{a.points} points, median of {a.runs} calls, 1 thread")
    print("| evaluation | numpy (ms) | compiled (ms) | speed-up | max relative difference |")
    print("|---|---|---|---|---|")
    for tangent in (False, True):
        ref = ogden_point_kernel(F, mat, tangent)
        got = point_kernel(F, mat, tangent)
        ok = np.isfinite(ref[0])
        diff = max(np.abs(g.reshape(a.points, -1)[ok] - r.reshape(a.points, -1)[ok]).max()
                   / np.abs(r.reshape(a.points, -1)[ok]).max()
                   for r, g in zip(ref[:3], got[:3]) if r is not None)
        t_np = median_time(lambda t=tangent: ogden_point_kernel(F, mat, t), a.runs)
        t_c = median_time(lambda t=tangent: point_kernel(F, mat, t), a.runs)
        label = "stress + tangent" if tangent else "stress"
        print(f"| {label} | {1e3 * t_np:.1f} | {1e3 * t_c:.1f} | {t_np / t_c:.1f}x | "
              f"{diff:.1e} |")


if __name__ == "__main__":
    main()
