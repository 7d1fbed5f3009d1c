"""The material of a simulation (numpy only, so the solver and the trainer share one type)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np


@dataclass(frozen=True)
class OgdenMaterial:
    """Parameters of the uncoupled Ogden law: c_k (MPa), m_k, bulk modulus K (MPa), and the
    volumetric energy ("log": K/2 (ln J)^2, FEBio's; "quadratic": K/2 (J - 1)^2).

    The one material type of the project: scenes, shards, the solver and the trainer use it.
    """

    law: ClassVar[str] = "ogden"
    c: tuple[float, ...]
    m: tuple[float, ...]
    K: float
    volumetric: str = "log"

    def __post_init__(self):
        c = tuple(float(x) for x in np.atleast_1d(self.c))
        m = tuple(float(x) for x in np.atleast_1d(self.m))
        object.__setattr__(self, "c", c)
        object.__setattr__(self, "m", m)
        object.__setattr__(self, "K", float(self.K))
        problems = []
        if len(c) != len(m) or not c:
            problems.append(f"c and m need one entry per term, got {len(c)} and {len(m)}")
        if any(not np.isfinite(x) or x <= 0 for x in c):
            problems.append(f"c must be finite and > 0, got {c}")
        if any(not np.isfinite(x) or x == 0 for x in m):
            problems.append(f"m must be finite and non-zero, got {m}")
        if not np.isfinite(self.K) or self.K <= 0:
            problems.append(f"K must be finite and > 0, got {self.K}")
        if self.volumetric not in ("log", "quadratic"):
            problems.append(f"volumetric must be 'log' or 'quadratic', got {self.volumetric!r}")
        if problems:
            raise ValueError("OgdenMaterial: " + "; ".join(problems))

    @property
    def mu(self) -> float:
        """Small-strain shear modulus sum(c)/2, MPa."""
        return 0.5 * sum(self.c)
