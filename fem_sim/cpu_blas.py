"""Pick OpenBLAS' kernels from the CPU's instruction sets, before OpenBLAS is loaded.

Why: Debian's OpenBLAS (and the one in numpy's wheels) chooses its kernels at load time from the
CPU's family and model numbers. Virtual machines often report a generic model ("Intel(R) Xeon(R)
Processor"), and then OpenBLAS falls back to its Prescott (SSE3) kernels: on such a
2-core VM with AVX-512 (``bench/bench_jacobian.py`` run with ``OPENBLAS_CORETYPE=Prescott`` and
without), a MUMPS factorisation takes about twice as long with the SSE3 kernels. Setting
``OPENBLAS_CORETYPE`` from the instruction sets the CPU reports in ``/proc/cpuinfo`` picks the
right kernels and is harmless where detection works (it names the same kernels).

Standard library only, so it runs before numpy: ``fem_sim/__init__.py`` calls :func:`configure`
when numpy is not loaded yet, the Makefile exports ``OPENBLAS_CORETYPE`` from this file run as a
script (``python fem_sim/cpu_blas.py`` prints the kernel set, or nothing), so every process it
starts, in either environment, loads the right kernels. A value the user set is kept.
"""

from __future__ import annotations

import os

# The widest kernel set whose instructions the CPU has (names as OpenBLAS' DYNAMIC_ARCH knows
# them); SkylakeX needs the AVX-512 foundation, CD, BW, DQ and VL subsets.
KERNELS = (
    ("SkylakeX", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}),
    ("Haswell", {"avx2", "fma"}),
    ("Sandybridge", {"avx"}),
)


def cpu_flags(path: str = "/proc/cpuinfo") -> set[str]:
    """Instruction-set flags of the first CPU (empty if unknown, e.g. not Linux)."""
    try:
        with open(path, encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def coretype(flags: set[str]) -> str | None:
    """OpenBLAS' kernel set for these flags, or None (leave OpenBLAS' own choice)."""
    for name, needs in KERNELS:
        if needs <= flags:
            return name
    return None


def configure(environ=os.environ, flags: set[str] | None = None) -> str | None:
    """Set OPENBLAS_CORETYPE unless already set; returns the value in force (or None).
    Only effective before OpenBLAS is loaded (before numpy, scipy or petsc4py is imported).
    """
    if environ.get("OPENBLAS_CORETYPE"):
        return environ["OPENBLAS_CORETYPE"]
    name = coretype(cpu_flags() if flags is None else flags)
    if name:
        environ["OPENBLAS_CORETYPE"] = name
    return name


if __name__ == "__main__":
    print(coretype(cpu_flags()) or "")
