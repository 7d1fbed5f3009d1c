"""Pictures of livers with pyvista: the surface shaded by displacement magnitude (colour bar in
mm), the undeformed outline, the fixed region and the force arrows.

One drawing for every place people look: ``fem_sim summary`` and ``make docs`` (solver
environment) and the surrogate's viewer (trainer environment) all draw through
:class:`LiverView`, so a liver looks the same everywhere. pyvista is imported on first use
(it needs an OpenGL: Mesa's EGL off-screen, or a window under X/Xvfb).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CMAP = "viridis"
LIVER = (0.72, 0.42, 0.36)
FIXED = "royalblue"
FORCE = "crimson"
# Seen from above and in front: both lobes and the vena-cava region (top, at the back) of the
# embedded phantom. A picture of a load turns this toward the loaded side (frame_camera).
VIEW = (0.3, -0.7, 1.0)


def pyvista():
    """The pyvista module, with a clear error when it is not installed, or when dolfinx is
    loaded in this process: VTK's wheel (old C++ string ABI) and dolfinx's C++ stack share
    template instances across libraries, and a render then dies in std::regex with
    std::bad_alloc (measured, VTK 9.7.2 beside dolfinx 0.5.2). Solve in one process, draw in
    another (scripts/render_phantoms.py does).
    """
    import os
    import sys

    if "dolfinx" in sys.modules:
        raise RuntimeError("pictures: dolfinx is loaded in this process and VTK would crash "
                           "beside it; render in a separate process")

    if not os.environ.get("DISPLAY"):  # no X server: straight to EGL (VTK would try X first)
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista as pv
    except ImportError as exc:  # pragma: no cover - environment problem
        raise ImportError("pictures need pyvista (make setup installs it into both "
                          f"environments): {exc}") from None
    return pv


@dataclass
class Surface:
    """A liver's boundary as a compact triangle mesh: ``nodes`` are the mesh node ids of its
    vertices, ``triangles`` index into ``nodes`` (outward orientation, as stored).
    """

    points: np.ndarray       # (n_surf, 3) undeformed vertex positions, mm
    triangles: np.ndarray    # (n_tri, 3) local ids
    nodes: np.ndarray        # (n_surf,) mesh node ids
    fixed: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # local ids

    @classmethod
    def from_mesh(cls, points, triangles, fixed=()) -> Surface:
        """From all mesh nodes and boundary triangles in mesh node ids."""
        points = np.asarray(points, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        if points.ndim != 2 or points.shape[1] != 3 or triangles.ndim != 2 or \
                triangles.shape[1] != 3 or triangles.size == 0:
            raise ValueError(f"surface: expected points (n, 3) and triangles (m, 3), got "
                             f"{points.shape} and {triangles.shape}")
        if triangles.min() < 0 or triangles.max() >= points.shape[0]:
            raise ValueError(f"surface: triangle node ids outside [0, {points.shape[0]})")
        nodes, local = np.unique(triangles, return_inverse=True)
        local_of = np.full(points.shape[0], -1)
        local_of[nodes] = np.arange(nodes.size)
        fixed = np.asarray(fixed, dtype=np.int64)
        fixed_local = local_of[fixed[local_of[fixed] >= 0]] if fixed.size else fixed
        return cls(points=points[nodes], triangles=local.reshape(-1, 3), nodes=nodes,
                   fixed=fixed_local)

    def local(self, mesh_nodes) -> np.ndarray:
        """Local ids of mesh node ids that lie on the surface (-1 for the others)."""
        mesh_nodes = np.asarray(mesh_nodes, dtype=np.int64)
        out = np.full(mesh_nodes.shape, -1, dtype=np.int64)
        pos = np.searchsorted(self.nodes, mesh_nodes)  # nodes are sorted (np.unique)
        hit = (pos < self.nodes.size) & (self.nodes[np.minimum(pos, self.nodes.size - 1)]
                                         == mesh_nodes)
        out[hit] = pos[hit]
        return out

    def normals(self) -> np.ndarray:
        """Outward unit vertex normals (area-weighted triangle normals)."""
        x, t = self.points, self.triangles
        fn = np.cross(x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]])
        n = np.zeros_like(x)
        for k in range(3):
            np.add.at(n, t[:, k], fn)
        return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)

    @property
    def size(self) -> float:
        """Diagonal of the bounding box, mm."""
        return float(np.linalg.norm(self.points.max(0) - self.points.min(0)))

    def polydata(self, points=None):
        pv = pyvista()
        t = self.triangles
        faces = np.hstack([np.full((t.shape[0], 1), 3), t]).ravel()
        return pv.PolyData(np.array(self.points if points is None else points, dtype=float),
                           faces)


def arrow_segments(anchors, forces, normals, length: float, f_ref: float):
    """(tails, vectors) of force arrows: length ``length * |f| / f_ref``, touching the surface
    at the anchor: an arrow that pushes into the liver ends at the node (its tail outside), one
    that pulls starts there. Pure numpy, so the drawing rule is testable without a renderer.
    """
    anchors, forces = np.atleast_2d(anchors), np.atleast_2d(forces)
    normals = np.atleast_2d(normals)
    mag = np.linalg.norm(forces, axis=1, keepdims=True)
    vec = forces / np.maximum(mag, 1e-300) * length * np.minimum(mag / f_ref, 1.5)
    pushes = np.sum(forces * normals, axis=1) < 0
    tails = np.where(pushes[:, None], anchors - vec, anchors)
    return tails, vec


class LiverView:
    """The actors of one liver in one viewport, updated in place for live views.

    ``update(u, forces, load_nodes)`` moves the surface to x + u (u per surface vertex, mm),
    colours it by |u| (or by ``scalars``), and redraws the force arrows at the load nodes
    (mesh node ids).
    """

    def __init__(self, plotter, surface: Surface, *, clim=None, title="displacement (mm)",
                 f_ref: float = 1.0, ghost: bool = True, scalar_bar: bool = True,
                 cmap: str = CMAP, label: str | None = None, solid: bool = False):
        pv = pyvista()
        self.plotter, self.surface, self.f_ref = plotter, surface, f_ref
        self.title = title
        self.mesh = surface.polydata()
        self.mesh[title] = np.zeros(surface.points.shape[0])
        self._normals = surface.normals()
        self.arrow_length = 0.18 * surface.size
        self.clim = clim
        if solid:  # a geometry without a field: the liver's own colour
            self._actor = plotter.add_mesh(self.mesh, color=LIVER, smooth_shading=True,
                                           specular=0.2)
        else:
            self._actor = plotter.add_mesh(
                self.mesh, scalars=title, cmap=cmap, clim=clim, smooth_shading=True,
                show_scalar_bar=scalar_bar, specular=0.2,
                scalar_bar_args={"title": title, "vertical": False, "fmt": "%.1f",
                                 "position_x": 0.25, "position_y": 0.02, "height": 0.1,
                                 "width": 0.5, "color": "black", "title_font_size": 16,
                                 "label_font_size": 14})
        bars = plotter.scalar_bars
        if scalar_bar and not solid and title in bars:
            bar = bars[title]
            bar.SetTextPositionToPrecedeScalarBar()  # labels below the bar, title above
        self.ghost_actor = None
        if ghost:  # the undeformed outline; translucent, so it costs a render pass
            self.ghost_actor = plotter.add_mesh(surface.polydata(), style="wireframe",
                                                color="gray", opacity=0.12, line_width=1)
        if surface.fixed.size:
            plotter.add_mesh(pv.PolyData(surface.points[surface.fixed]), color=FIXED,
                             point_size=7, render_points_as_spheres=True)
        self.arrows = pv.PolyData()  # refilled in place by update()
        plotter.add_mesh(self.arrows, color=FORCE, smooth_shading=True)
        if label:
            plotter.add_text(label, position="upper_left", font_size=11, color="black")

    def update(self, u, forces=(), load_nodes=(), scalars=None) -> None:
        pv = pyvista()
        u = np.asarray(u, dtype=float)
        x = self.surface.points + u
        self.mesh.points = x
        values = np.linalg.norm(u, axis=1) if scalars is None else np.asarray(scalars)
        self.mesh[self.title] = values
        if self.clim is None:  # no fixed range: the colours span this field's values
            self._actor.mapper.scalar_range = (0.0, max(float(values.max()), 1e-9))
        forces = np.asarray(forces, dtype=float).reshape(-1, 3)
        loc = self.surface.local(load_nodes) if len(load_nodes) else np.zeros(0, int)
        arrows = []
        for f, i in zip(forces, loc):
            if i < 0 or not np.linalg.norm(f) > 0:
                continue  # a load off the surface (patch centre inside) is not drawn
            tail, vec = arrow_segments(x[i], f, self._normals[i], self.arrow_length, self.f_ref)
            length = float(np.linalg.norm(vec))
            arrows.append(pv.Arrow(start=tail[0], direction=vec[0], scale=length, tip_length=0.3,
                                   tip_radius=0.12, shaft_radius=0.045))
        merged = arrows[0].merge(arrows[1:]) if arrows else pv.PolyData()
        self.arrows.copy_from(merged)


def view_toward(surface: Surface, nodes=()) -> np.ndarray:
    """The camera direction (from the liver to the eye): :data:`VIEW`, turned toward the mean
    outward normal at ``nodes`` (mesh ids on the surface) so that loads there are in sight.
    """
    v = np.asarray(VIEW, float) / np.linalg.norm(VIEW)
    loc = surface.local(nodes) if len(nodes) else np.zeros(0, int)
    loc = loc[loc >= 0]
    if loc.size:
        n = surface.normals()[loc].sum(axis=0)
        w = v + 1.5 * n / max(np.linalg.norm(n), 1e-12)
        if np.linalg.norm(w) > 0.3:
            v = w / np.linalg.norm(w)
    return v


def frame_camera(plotter, surface: Surface, nodes=(), zoom: float = 1.2,
                 everything: bool = False, margin: float = 0.0) -> None:
    """Point the active viewport's camera at the liver from :func:`view_toward`; framing the
    liver's bounds grown by ``margin`` mm on every side (room for the liver to move), or
    ``everything`` drawn (arrows included).
    """
    v = view_toward(surface, nodes)
    up = (0, 1, 0) if abs(v[2]) > 0.95 else (0, 0, 1)
    plotter.view_vector(v, viewup=up)
    if everything:
        plotter.reset_camera()
    else:
        b = np.asarray(surface.polydata().bounds, np.float64)
        plotter.reset_camera(bounds=b + np.tile([-margin, margin], 3))
    plotter.camera.zoom(zoom)


@dataclass
class Panel:
    """One viewport of a still picture: a surface, its displacement and loads, a label."""

    surface: Surface
    u: np.ndarray | None = None            # per surface vertex, mm (None: undeformed)
    forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    load_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    label: str = ""
    scalars: np.ndarray | None = None      # colour values instead of |u|
    title: str = "displacement (mm)"
    clim: tuple | None = None
    cmap: str = CMAP
    f_ref: float = 1.0


def draw_panels(plotter, panels: list[Panel], cols: int, first_row: int = 0) -> None:
    """Draw panels into a plotter's subplots, row by row from ``first_row``. Panels with the
    same colour-bar title share one colour range (pyvista draws one bar per title), so livers
    next to each other compare at a glance.
    """
    top: dict[str, float] = {}
    for panel in panels:
        if panel.u is not None and panel.clim is None:
            v = (np.linalg.norm(panel.u, axis=1) if panel.scalars is None else panel.scalars)
            top[panel.title] = max(top.get(panel.title, 1e-9), float(np.max(v)))
    for k, panel in enumerate(panels):
        plotter.subplot(first_row + k // cols, k % cols)
        clim = None if panel.u is None else (panel.clim or (0.0, top[panel.title]))
        view = LiverView(plotter, panel.surface, clim=clim, title=panel.title,
                         f_ref=panel.f_ref, cmap=panel.cmap, label=panel.label,
                         ghost=panel.u is not None, solid=panel.u is None)
        if panel.u is not None:
            view.update(panel.u, panel.forces, panel.load_nodes, scalars=panel.scalars)
        frame_camera(plotter, panel.surface, panel.load_nodes, zoom=1.1, everything=True)


def render_panels(panels: list[Panel], out_png, *, title: str = "", cols: int | None = None,
                  panel_size=(560, 480)) -> Path:
    """Render panels side by side (off-screen, :func:`draw_panels`) into one PNG; returns its
    path.
    """
    pv = pyvista()
    n = len(panels)
    cols = cols or n
    rows = (n + cols - 1) // cols
    header = 44 if title else 0
    size = (panel_size[0] * cols, panel_size[1] * rows + header)
    if title:  # a header row spanning all columns, so the title covers no liver
        p = pv.Plotter(off_screen=True, shape=(rows + 1, cols), border=False, window_size=size,
                       row_weights=[header / panel_size[1]] + [1] * rows,
                       groups=[(0, np.s_[:])])
        p.subplot(0, 0)
        p.add_text(title, position="upper_edge", font_size=13, color="black")
    else:
        p = pv.Plotter(off_screen=True, shape=(rows, cols), border=False, window_size=size)
    p.set_background("white")
    draw_panels(p, panels, cols, first_row=1 if title else 0)
    out = Path(out_png)
    out.parent.mkdir(parents=True, exist_ok=True)
    p.screenshot(str(out))
    p.close()
    return out


def write_gif(frames, path, fps: float = 10.0) -> Path:
    """An animated GIF (looping) from RGB frames (uint8 arrays), through Pillow."""
    from PIL import Image

    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    if not images:
        raise ValueError(f"{path}: no frames to write")
    images = [im.convert("P", palette=Image.Palette.ADAPTIVE, colors=255) for im in images]
    path = Path(path)
    images[0].save(path, save_all=True, append_images=images[1:], loop=0,
                   duration=int(round(1000 / fps)), optimize=True, disposal=2)
    return path
