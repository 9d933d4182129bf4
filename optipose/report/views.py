"""A picture of a part and a sensor layout, to check the layout at a glance (``optipose show``).

Orthographic views (isometric and front of the whole cell; front and top close-ups of the part) of the part's surface and sharp edges, each
sensor's head box (wireframe), its laser fan from the window to the far end of the range, the measuring
trapezoid (filled), and the points of a nominal scan, one colour per sensor. Axes in millimetres.
"""

from __future__ import annotations

import weakref
from pathlib import Path

import numpy as np

from optipose.files import atomic_path
from optipose.model.layout import Layout
from optipose.model.sensor import load_sensor
from optipose.scan.scanner import part_scanner, registered_motion
from optipose.transforms import transform_points

__all__ = ["render_part", "render_layouts", "drawn_mesh"]

# (title, elevation, azimuth, zoomed on the part): whole scene for the heads, close-ups for the points.
_VIEWS = (
    ("isometric", 28.0, -58.0, False),
    ("front, looking along -x", 0.0, 0.0, False),
    ("front, close-up", 0.0, 0.0, True),
    ("top, close-up", 90.0, -90.0, True),
)
_ZOOM_MARGIN_MM = 8.0
_BOX_EDGES = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
_MAX_POINTS = 4000  # per sensor in the picture; matplotlib 3D gets slow and muddy beyond that
_SHARP_DEG = 30.0
_MAX_TRIANGLES = 50_000  # drawn at most: a dense CAD export is simplified to this many for the picture
_LAST: dict = {}  # what the views of the last mesh drawn share: its simplification, sharp edges and scanners


def render_part(part, out: str | Path, layout: str | None = "hand", scans: dict | None = None) -> Path:
    """Save a PNG of ``part`` with the sensors of ``part.layouts[layout]`` and their nominal scans.

    scans : optional {sensor name: (n, 3) points, m}; scanned here (nominal pose, no noise) when None.
    Returns the written path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lay = part.layouts.get(layout) if layout else None
    if scans is None:
        scans = _nominal_points(part, lay) if lay else {}
    fig = plt.figure(figsize=(14, 13), dpi=100)
    colours = plt.get_cmap("tab10").colors
    for k, (title, elev, azim, zoom) in enumerate(_VIEWS):
        ax = fig.add_subplot(2, 2, k + 1, projection="3d", computed_zorder=False)
        _draw_part(ax, part)
        if lay:
            _draw_sensors(ax, part, lay, scans, colours)
        bounds = (part.mesh.bounds * 1e3 + [[-_ZOOM_MARGIN_MM], [_ZOOM_MARGIN_MM]]) if zoom else _data_bounds(ax)
        _frame(ax, title, elev, azim, bounds)
    size = " x ".join(f"{v:.1f}" for v in part.size * 1e3)
    label = f"layout '{layout}' ({len(lay)} sensors)" if lay else "no layout"
    fig.suptitle(f"{part.name}: {size} mm, {part.material}, scan {part.motion.length * 1e3:g} mm along +x — {label}")
    if lay:
        handles = [plt.Line2D([], [], color=colours[i % 10], lw=3) for i in range(len(lay))]
        names = [f"{s.name}: {len(scans.get(s.name, ()))} pts" for s in lay.sensors]
        fig.legend(handles, names, loc="lower center", ncol=len(names), frameon=False)
    fig.subplots_adjust(left=0.02, right=0.98, bottom=0.04, top=0.93, wspace=0.05, hspace=0.1)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:  # never half a picture where the report takes it from
        fig.savefig(tmp, format=out.suffix.lstrip(".").lower() or "png")
    plt.close(fig)
    return out


def render_layouts(part, names: list[str], folder: Path, jobs: int = 1) -> list[Path]:
    """``folder/<name>.png`` of each of ``part.layouts[name]`` (:func:`render_part`), one picture a task on ``jobs``
    local worker processes (joblib's, which write to this machine's folder; in this process with one). A picture
    that fails is a warning and left out: a picture must never cost the results."""
    import logging
    from functools import partial

    from optipose.parallel.executors import make_executor

    executor = make_executor(jobs)  # the pool the search's evaluations warmed, reused
    try:
        drawn = executor.map(partial(_render_named, part, Path(folder)), names)
    except Exception as exc:  # a worker that died twice: no pictures, the results stand
        logging.getLogger(__name__).warning("could not draw the layouts: %s", exc)
        return []
    finally:
        executor.close()
    return [path for path in drawn if path is not None]


def _render_named(part, folder: Path, name: str) -> Path | None:
    try:
        return render_part(part, folder / f"{name}.png", name)
    except Exception as exc:
        import logging

        logging.getLogger(__name__).warning("could not draw %s: %s", name, exc)
        return None


def _kept(mesh, key, make):
    """``make()``, kept while ``mesh`` is the last mesh drawn: the four views of a picture, and the pictures of
    one part's layouts (a search draws one per k), simplify it and build its scanner once."""
    held = _LAST.get("mesh")
    if held is None or held() is not mesh:
        _LAST.clear()
        _LAST["mesh"] = weakref.ref(mesh, lambda ref: _LAST.clear() if _LAST.get("mesh") is ref else None)
    if key not in _LAST:
        _LAST[key] = make()
    return _LAST[key]


def _nominal_points(part, layout: Layout) -> dict[str, np.ndarray]:
    occluders = tuple(np.asarray(b, float).tobytes() for box in part.occluders for b in box)
    scanner = _kept(part.mesh, ("scanner", part.sensor, part.material, occluders), lambda: part_scanner(part))
    # a long part in the evaluation's longer steps: the picture draws a few thousand points
    scans = scanner.scan_many(layout.poses, registered_motion(part.motion), noise=False)
    return {s.name: scan.points for s, scan in zip(layout.sensors, scans)}


def _draw_part(ax, part) -> None:
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    mm, triangles, sharp = _kept(part.mesh, "drawn", lambda: _drawn_arrays(part.mesh))
    ax.add_collection3d(
        Poly3DCollection(triangles, facecolor=(0.80, 0.82, 0.86, 0.30), edgecolor="none", axlim_clip=True, zorder=1)
    )
    ax.add_collection3d(Line3DCollection(mm[sharp], colors="0.25", linewidths=0.6, axlim_clip=True, zorder=2))
    for keepout in part.keepouts:
        lo, hi = keepout.lo * 1e3, keepout.hi * 1e3
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        ax.add_collection3d(
            Line3DCollection(
                corners[_BOX_EDGES], colors="0.55", linewidths=0.8, linestyles=":", axlim_clip=True, zorder=2
            )
        )


def _drawn_arrays(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The drawn mesh's vertices (mm), triangles (t, 3, 3) mm and sharp edges (e, 2) vertex indices."""
    mesh = drawn_mesh(mesh)
    mm = mesh.vertices * 1e3
    return mm, mm[mesh.faces], mesh.face_adjacency_edges[mesh.face_adjacency_angles > np.deg2rad(_SHARP_DEG)]


def drawn_mesh(mesh, max_triangles: int = _MAX_TRIANGLES):
    """The mesh the views draw: ``mesh`` itself up to ``max_triangles`` triangles, else a vertex-clustering
    simplification (Open3D; linear in the mesh) with at most that many, its cells sized from the surface
    area, grown until it fits. matplotlib draws every triangle one by one: a million-triangle CAD export
    would take minutes, for a picture no finer than its pixels."""
    if len(mesh.faces) <= max_triangles:
        return mesh
    import open3d as o3d
    import trimesh

    full = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(mesh.vertices, dtype=np.float64)),
        o3d.utility.Vector3iVector(np.asarray(mesh.faces, dtype=np.int32)),
    )
    cell = np.sqrt(2.0 * float(mesh.area) / max_triangles)  # about two triangles per cell of the surface
    while True:
        few = full.simplify_vertex_clustering(voxel_size=cell)
        if len(few.triangles) <= max_triangles:
            return trimesh.Trimesh(np.asarray(few.vertices), np.asarray(few.triangles), process=False)
        cell *= 1.25


def _draw_sensors(ax, part, layout: Layout, scans: dict, colours) -> None:
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    for i, pose in enumerate(layout.sensors):
        colour = colours[i % 10]
        sensor = load_sensor(pose.sensor or part.sensor)
        T = pose.T_O_S
        head = transform_points(T, sensor.head_box_corners()) * 1e3
        ax.add_collection3d(Line3DCollection(head[_BOX_EDGES], colors=[colour], linewidths=1.2, axlim_clip=True))
        trapezoid, fan = _fan_S(sensor)
        ax.add_collection3d(
            Poly3DCollection(
                [transform_points(T, trapezoid) * 1e3],
                facecolor=(*colour, 0.08),
                edgecolor=colour,
                linewidths=0.8,
                axlim_clip=True,
                zorder=3,
            )
        )
        ax.add_collection3d(
            Line3DCollection(
                transform_points(T, fan).reshape(-1, 2, 3) * 1e3,
                colors=[colour],
                linewidths=0.6,
                linestyles="--",
                axlim_clip=True,
                zorder=3,
            )
        )
        pts = scans.get(pose.name)
        if pts is not None and len(pts):
            pick = np.random.default_rng(i).choice(len(pts), min(len(pts), _MAX_POINTS), replace=False)
            p = pts[pick] * 1e3
            ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1.0, color=colour, depthshade=False, axlim_clip=True, zorder=4)
        label = transform_points(T, np.array([[0.0, 0.0, sensor.window_z - 0.5 * sensor.head_box[2]]]))[0]
        ax.text(*(label * 1e3), pose.name, color=colour, fontsize=10, fontweight="bold", axlim_clip=True, zorder=5)
        ax.scatter(*(T[:3, 3] * 1e3), color=colour, s=20, marker="x", axlim_clip=True, zorder=5)  # R


def _fan_S(sensor) -> tuple[np.ndarray, np.ndarray]:
    """The measuring trapezoid (4, 3) and the fan's two outer rays window→far end ((4, 3): 2 segments), in S."""
    hn, hf = 0.5 * sensor.width_near, 0.5 * sensor.width_far
    zn, zf = sensor.z_near, sensor.z_far
    trapezoid = np.array([[-hn, 0, zn], [hn, 0, zn], [hf, 0, zf], [-hf, 0, zf]])
    hw = float(sensor.half_width(sensor.window_z)) if np.isfinite(sensor.apex_z) else hn
    fan = np.array([[-hw, 0, sensor.window_z], [-hf, 0, zf], [hw, 0, sensor.window_z], [hf, 0, zf]])
    return trapezoid, fan


def _frame(ax, title: str, elev: float, azim: float, bounds) -> None:
    """Equal-scale orthographic axes around ``bounds`` ((2, 3) mm), seen from a view direction."""
    ax.set_proj_type("ortho")
    ax.view_init(elev=elev, azim=azim)
    lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    centre, half = 0.5 * (lo + hi), 0.5 * float(np.max(hi - lo)) * 1.02
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1), zoom=1.2)
    ax.set_title(title, y=0.98)
    hidden = "z" if elev == 90.0 else ("x" if elev == 0.0 else "")  # the axis seen end-on
    for axis in "xyz":
        if axis == hidden:
            getattr(ax, f"set_{axis}ticks")([])
        else:
            getattr(ax, f"set_{axis}label")(f"{axis} (mm)")


def _data_bounds(ax) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (3,), (3,) in mm of the line collections drawn on ``ax`` (part edges, heads, fans)."""
    pts = []
    for coll in ax.collections:
        segs = getattr(coll, "_segments3d", None)
        if segs is not None and len(segs):
            pts.append(np.asarray(segs, dtype=float).reshape(-1, 3))
    allp = np.concatenate(pts)
    return allp.min(axis=0), allp.max(axis=0)
