"""Put the project on a virtual environment's path, and choose OpenBLAS' kernels at every start.

    VENV/bin/python scripts/install_pth.py ROOT

Writes two ``.pth`` files into the environment's site-packages: ``liverfem.pth`` (the project
root, so ``import fem_sim`` works with no build step) and ``liverfem_blas.pth`` (runs
``data_spec/cpu_blas.py``'s ``configure()`` when the interpreter starts, before anything loads
OpenBLAS). Idempotent; ``make setup`` runs it on each environment.
"""

import sys
import sysconfig
from pathlib import Path

root = Path(sys.argv[1]).resolve()
site = Path(sysconfig.get_paths()["purelib"])
(site / "liverfem.pth").write_text(f"{root}\n")
blas = root / "data_spec" / "cpu_blas.py"
(site / "liverfem_blas.pth").write_text(
    f"import runpy; runpy.run_path({str(blas)!r})['configure']()\n")
