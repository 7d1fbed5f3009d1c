"""Type predicates shared by every validator of the project (scene, solver settings, trainer
config): booleans are not integers, and a number must be finite.
"""

from __future__ import annotations

import math
from typing import Any


def is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def is_num(v: Any) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool)) and math.isfinite(v)
