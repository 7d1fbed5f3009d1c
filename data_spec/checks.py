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


def positive_number(text: str, why: str = "") -> float:
    """An argparse ``type``: a finite number > 0 (a mesh size, a scale), else the parser's
    error naming the flag and the value (``why``: said after it).
    """
    import argparse

    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}{why}")
    return value


def scale_factor(text: str) -> float:
    """An argparse ``type``: a length scale (> 0: a negative one would mirror the liver)."""
    return positive_number(text, " (a negative scale would mirror the liver, zero collapse "
                           "it: 1000 for a file in metres, 10 for centimetres)")


def count(text: str) -> int:
    """An argparse ``type``: a whole number >= 0 (a number of simulations or loads)."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value
