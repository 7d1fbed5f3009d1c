"""The one check of a liver's length unit, for both sides: a liver spans 30-600 mm."""

from __future__ import annotations

LIVER_SPAN_MM = (30.0, 600.0)


def span_problem(span: float, where: str, flag: str = "--scale-to-mm") -> str | None:
    """None when a liver spanning ``span`` file units is plausibly in mm; else what to set
    (``flag``: the command-line flag or scene key that scales the file).
    """
    lo, hi = LIVER_SPAN_MM
    if lo <= span <= hi:
        return None
    said = f"{where}: the liver spans {span:.3g} file units; a liver in mm spans {lo:g}-{hi:g}"
    if span < lo:
        guess = 1000 if span * 1000 <= hi else 10
        unit = "metres" if guess == 1000 else "centimetres"
        return f"{said}: if the file is in {unit}, give {flag} {guess}"
    return (f"{said}: it is too large for millimetres (a file in tenths of a mm needs {flag} "
            "0.1; otherwise it is not one liver)")
