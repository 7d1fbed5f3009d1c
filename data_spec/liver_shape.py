"""Whether a surface is plausibly a liver: its volume, its extents along its principal axes
and how much of their box it fills, against the range of real livers (said as a warning with
the figures: a phantom or an animal organ may be meant); and whether a file's pieces are one
liver and its specks (refused otherwise: two livers, or a liver in parts).

numpy only, for both environments.
"""

from __future__ import annotations

import numpy as np

# (min, max) over the 161 CT livers and the SOFA liver of ../shared/data/livers (largest piece,
# holes closed): volume in mL, extents in mm along the principal axes (largest first), and the
# fill = volume / (product of the extents). tests/reliability checks every shared liver lies
# within them.
LIVER_RANGE = {
    "volume_ml": (669.0, 3329.0),
    "extent_1_mm": (167.4, 298.8),
    "extent_2_mm": (115.6, 219.3),
    "extent_3_mm": (100.6, 168.5),
    "fill": (0.195, 0.396),
}
FAR = 1.5   # "far outside": below min / FAR or above max * FAR
# A file's pieces beside the largest: specks are dropped (reported); a piece enclosing more
# than this fraction of the largest one's volume is refused (two livers, a liver in parts).
PIECE_FRACTION = 0.05


def pieces_problem(where: str, volumes_ml, option: str) -> str | None:
    """Why a file's pieces (the volumes they enclose, mL, the largest first) are not one
    liver and its specks, naming both largest volumes and ``option``, what meshes the largest
    anyway (None when every other piece is a speck).
    """
    if len(volumes_ml) < 2 or volumes_ml[1] <= PIECE_FRACTION * volumes_ml[0]:
        return None
    first, second = volumes_ml[0], volumes_ml[1]
    return (f"{where}: {len(volumes_ml)} separate pieces: the largest encloses {first:.0f} mL, "
            f"the next {second:.0f} mL ({second / first:.0%} of it, beyond "
            f"{PIECE_FRACTION:.0%}): two livers, or a liver in parts? To mesh the largest "
            f"alone: {option}")


def shape_figures(points, volume_ml: float) -> dict:
    """The figures of :data:`LIVER_RANGE` for a surface's ``points`` (n, 3) mm enclosing
    ``volume_ml``.
    """
    x = np.asarray(points, dtype=np.float64)
    x = x - x.mean(axis=0)
    _, axes = np.linalg.eigh(np.cov(x.T))
    extents = np.sort(np.ptp(x @ axes, axis=0))[::-1]
    box = float(np.prod(extents))
    return {"volume_ml": float(volume_ml), "extent_1_mm": float(extents[0]),
            "extent_2_mm": float(extents[1]), "extent_3_mm": float(extents[2]),
            "fill": volume_ml * 1e3 / box if box > 0 else float("inf")}


def surface_volume_ml(points, triangles) -> float:
    """ML enclosed by a closed triangle surface (divergence theorem; either facing)."""
    x = np.asarray(points, dtype=np.float64)[np.asarray(triangles)]
    return abs(float(np.einsum("ij,ij->", x[:, 0], np.cross(x[:, 1], x[:, 2])))) / 6e3


def unlike_a_liver(points, volume_ml: float, where: str) -> str | None:
    """A warning naming ``where`` and every figure far outside the livers' range (None when
    the surface is plausibly a liver).
    """
    figures = shape_figures(points, volume_ml)
    far = [f"{name} {value:.3g} (livers {lo:g}-{hi:g})"
           for name, value in figures.items()
           for lo, hi in [LIVER_RANGE[name]] if not lo / FAR <= value <= hi * FAR]
    if not far:
        return None
    return (f"{where}: not shaped like a liver: {'; '.join(far)}; meshed as asked (a "
            "liver in another unit needs its scale; two organs or a part need cutting)")
