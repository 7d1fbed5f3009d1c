"""``liverfem-sim mesh LIVER --mesh-size H --out FILE``: one liver surface repaired and meshed
(:mod:`fem_sim.geometry.repair`; ``--scene SCENE``: at its mesh size, as that population's
livers were meshed), written as a data_spec geometry file (what a file scene, a
population and the truth of a liver never seen read), with its repair report (FILE's stem +
``.repair.json``) and a picture (``.png``: input against meshed surface, mesh quality).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def _outputs(out: Path) -> tuple[Path, Path]:
    stem = out.with_suffix("")
    return stem.with_name(stem.name + ".repair.json"), stem.with_name(stem.name + ".png")


def mesh_size_of(args) -> tuple[float | None, float]:
    """(mesh size mm, scale to mm) of ``liverfem-sim mesh``: its --mesh-size, or its --scene's
    mesh size (None, with the reason printed, for a scene that cannot be read).
    """
    if args.scene is None:
        return args.mesh_size, args.scale_to_mm
    from data_spec import SceneError, load_scene

    try:
        return float(load_scene(args.scene)["geometry"]["mesh_size"]), args.scale_to_mm
    except (SceneError, OSError) as exc:
        print(f"liverfem-sim mesh: --scene {args.scene}: {exc}", file=sys.stderr)
        return None, 1.0


def run(liver: str, mesh_size: float, out: str, scale_to_mm: float = 1.0,
        picture: bool = True, keep_largest: bool = False) -> int:
    from data_spec.atomic import out_problem, write_text_atomic
    from data_spec.geometry import write_geometry
    from fem_sim.geometry.errors import GeometryError
    from fem_sim.geometry.repair import edges_of, mesh_liver_surface, read_any_surface

    out = Path(out)
    report_path, png = _outputs(out)
    why = (f"--out {out}: expected a .h5 data_spec geometry file"
           if out.suffix not in (".h5", ".hdf5") else
           next(filter(None, (out_problem(p) for p in (out, report_path, png))), None))
    if why:   # before any work: a bad --out is not found after the meshing
        print(f"liverfem-sim mesh: {why}", file=sys.stderr)
        return 2
    try:
        points, tris = read_any_surface(liver)
        g, report = mesh_liver_surface(points, tris, mesh_size, str(liver), scale_to_mm,
                                       keep_largest=keep_largest)
    except (GeometryError, ValueError) as exc:
        print(f"liverfem-sim mesh: {exc}", file=sys.stderr)
        return 2
    write_geometry(out, g)
    write_text_atomic(report_path, json.dumps(report.to_dict(), indent=1))
    print(report.summary())
    for msg in report.warnings:
        print(f"warning: {msg}", file=sys.stderr)
    if picture:
        from fem_sim.geometry.quality import dihedral_angles
        from liverviz.repair_picture import repair_picture

        edges, counts = edges_of(tris)
        repair_picture(png, points * scale_to_mm, tris, edges[counts == 1], g.points,
                       g.surface_triangles, dihedral_angles(g.points, g.cells).min(axis=1),
                       report.summary())
    print(f"wrote {out}, {report_path}" + (f", {png}" if picture else ""))
    return 0
