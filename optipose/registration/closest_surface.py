"""Compiled closest points on a planar-faced mesh (numba, ``nogil``): each point's closest point on the faces
that cross the cells of a grid over the part around it (the grid and the other arrays searched are built once per
part in :mod:`optipose.registration.surface_index`), starting from the face it had at the last step (walking
across the edge it left by) before its grid cell's faces are searched. The arithmetic is documented in
:mod:`optipose.registration.reference` (:class:`~optipose.registration.reference.SurfaceReference`);
compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["nearest_into", "edge_normal", "CREASE_DEG"]

_WALK = 4  # faces a point that left its face's guess walks across before the grid is searched
CREASE_DEG = (
    1.0  # a fold between two faces sharper than this is a crease (an edge of the part, not of its tessellation)
)
_CREASE_COS = float(np.cos(np.deg2rad(CREASE_DEG)))
# m: a point keeps a face for the faces of its plane around it (:func:`_in_plane`) only this near the plane. A
# cloud of the part as made lies within a tenth of a millimetre of the CAD; a point farther may be past the
# middle of a thin wall, whose other side the search must see (a wall thicker than twice this is safe).
_KEEP_NEAR = 0.25e-3
_PATCH = 16  # faces of one plane a point's disc may cover before the search decides instead
_FOLD = 1e-8  # m: how far off a face's plane the face across an edge must reach to turn away from it


@njit(cache=True, nogil=True, inline="always")
def _closest_on_triangle(px, py, pz, a, b, c):
    """Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection §5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2]
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2]
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2]
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w


@njit(cache=True, nogil=True, inline="always")
def _project(p, i, f, planes, plane_c, q):
    """Project p[i] on face f's plane into q[i]; True when it lies inside the face by more than 2|d|."""
    h0 = planes[f, 0, 0] * p[i, 0] + planes[f, 0, 1] * p[i, 1] + planes[f, 0, 2] * p[i, 2] - plane_c[f, 0]
    inset = np.inf
    for k in range(1, 4):
        hk = planes[f, k, 0] * p[i, 0] + planes[f, k, 1] * p[i, 1] + planes[f, k, 2] * p[i, 2] - plane_c[f, k]
        inset = min(inset, hk)
    for j in range(3):
        q[i, j] = p[i, j] - h0 * planes[f, 0, j]
    return inset > 2.0 * abs(h0), inset >= 0.0


@njit(cache=True, nogil=True)
def _in_plane(p, i, f, planes, plane_c, tri, adjacent, paired, plane_id, q, seen):
    """For a point that :func:`_project` does not keep on face f: whether it projects into f and, within
    ``_KEEP_NEAR`` of the plane, the disc of radius 2|d| about its projection lies in the faces of f's plane
    around it (:func:`_disc_in_plane`) — across the edges of the tessellation, not of the part, which a cloud
    a few tens of µm off the CAD crosses everywhere. Then no face can be nearer than the projection (written
    into q[i]). Out of line: inlined into the search it slowed every point."""
    h0 = planes[f, 0, 0] * p[i, 0] + planes[f, 0, 1] * p[i, 1] + planes[f, 0, 2] * p[i, 2] - plane_c[f, 0]
    if abs(h0) > _KEEP_NEAR:
        return False
    for k in range(1, 4):  # inside f, off its edges by more than rounding: on an edge the search's lowest id decides
        hk = planes[f, k, 0] * p[i, 0] + planes[f, k, 1] * p[i, 1] + planes[f, k, 2] * p[i, 2] - plane_c[f, k]
        if hk <= 0.0 or hk * hk <= 1e-6 * h0 * h0 + 1e-18:
            return False
    if not _disc_in_plane(p, i, f, h0, tri, planes, plane_c, adjacent, paired, plane_id, seen):
        return False
    for j in range(3):
        q[i, j] = p[i, j] - h0 * planes[f, 0, j]
    return True


@njit(cache=True, nogil=True)
def _disc_in_plane(p, i, f, h0, tri, planes, plane_c, adjacent, paired, plane_id, seen):
    """Whether the disc of radius 2|h0| about p[i]'s projection on face f's plane lies in the faces of that
    plane connected to f: the faces it covers are visited across the edges it crosses (at most ``_PATCH``), and
    none of those edges may be the plane's border (no face across, more than one (``paired``), or one in another
    plane) — unless it lies farther than |h0| from the projection and the face across turns away from the point
    (:func:`_folds_away`): then nothing within |h0| of the point lies beyond it but what the search's trust
    excludes anyway (a slot, a thin wall's other side). The disc is convex and starts inside f, so it cannot
    leave the plane's faces without crossing such an edge. ``seen`` (``_PATCH``,) int64: the caller's scratch for
    the faces visited (allocated once per call of :func:`nearest_into`, not once per point)."""
    x0 = p[i, 0] - h0 * planes[f, 0, 0]
    x1 = p[i, 1] - h0 * planes[f, 0, 1]
    x2 = p[i, 2] - h0 * planes[f, 0, 2]
    r2 = 4.0 * h0 * h0
    seen[0], n, head = f, 1, 0
    while head < n:
        g = seen[head]
        head += 1
        for k in range(3):
            # the edge's line first (its inward plane, four loads): a disc that misses the line misses the edge; the
            # margin keeps rounding from skipping an edge the exact distance below would call reached
            hk = planes[g, k + 1, 0] * x0 + planes[g, k + 1, 1] * x1 + planes[g, k + 1, 2] * x2 - plane_c[g, k + 1]
            if hk * hk >= r2 * (1.0 + 1e-9) + 1e-24:
                continue
            a, b = tri[g, k], tri[g, (k + 1) % 3]
            e0, e1, e2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
            t = ((x0 - a[0]) * e0 + (x1 - a[1]) * e1 + (x2 - a[2]) * e2) / max(e0 * e0 + e1 * e1 + e2 * e2, 1e-300)
            t = min(max(t, 0.0), 1.0)
            d0, d1, d2 = x0 - a[0] - t * e0, x1 - a[1] - t * e1, x2 - a[2] - t * e2
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            if dist2 >= r2:
                continue  # the disc does not reach this edge
            h = adjacent[g, k]
            if h < 0 or not (paired[g] >> k) & 1:
                return False
            if plane_id[h] != plane_id[f]:
                if dist2 > h0 * h0 and _folds_away(h, f, h0, tri, planes, plane_c):
                    continue  # an edge of the part, farther than |d|, that turns away from the point
                return False
            known = False
            for m in range(n):
                known = known or seen[m] == h
            if not known:
                if n == _PATCH:
                    return False
                seen[n] = h
                n += 1
    return True


@njit(cache=True, nogil=True, inline="always")
def _folds_away(h, f, h0, tri, planes, plane_c):
    """Whether face h, across an edge of face f's plane, lies on the side of that plane away from the point
    (h0: its signed distance from it): then every point of h is farther from the point than |h0|, the
    distance of its projection on f."""
    far = 0.0
    for m in range(3):
        s = (
            planes[f, 0, 0] * tri[h, m, 0]
            + planes[f, 0, 1] * tri[h, m, 1]
            + planes[f, 0, 2] * tri[h, m, 2]
            - plane_c[f, 0]
        )
        if abs(s) > abs(far):
            far = s
    return far * h0 < 0.0 and abs(far) > _FOLD  # a face in the plane to rounding (a sliver, a flipped face) is not


@njit(cache=True, nogil=True, inline="always")
def _gap(x, lo, cell):
    """The square of how far x lies outside the slab [lo, lo + cell]."""
    d = max(lo - x, x - lo - cell, 0.0)
    return d * d


@njit(cache=True, nogil=True, inline="always")
def _inset2(p, i, f, planes, plane_c):
    """The square of how far inside face f's edges p[i] projects, or -1 where it projects outside."""
    inset = np.inf
    for k in range(1, 4):
        inset = min(
            inset, planes[f, k, 0] * p[i, 0] + planes[f, k, 1] * p[i, 1] + planes[f, k, 2] * p[i, 2] - plane_c[f, k]
        )
    return inset * inset if inset > 0.0 else -1.0


@njit(cache=True, nogil=True, inline="always")
def _walk(p, i, f, planes, plane_c, tri, adjacent, paired, plane_id, q, seen):
    """From face f toward the face p[i] projects into: across the edge it lies farthest outside of, to the
    face on the other side (``adjacent`` (f, 3): across edge k, -1 for none), at most ``_WALK`` faces. Returns
    the first face that keeps it (:func:`_project`, :func:`_in_plane`; its projection in q[i]), or -1."""
    g = f
    for _ in range(_WALK):
        worst, k_out = np.inf, -1
        for k in range(1, 4):
            hk = planes[g, k, 0] * p[i, 0] + planes[g, k, 1] * p[i, 1] + planes[g, k, 2] * p[i, 2] - plane_c[g, k]
            if hk < worst:
                worst, k_out = hk, k - 1
        if worst >= 0.0:  # it projects inside g, only too near an edge for its distance: no face is surer
            return -1
        g = adjacent[g, k_out]
        if g < 0:
            return -1
        if _project(p, i, g, planes, plane_c, q)[0] or _in_plane(
            p, i, g, planes, plane_c, tri, adjacent, paired, plane_id, q, seen
        ):
            return g
    return -1


@njit(cache=True, nogil=True)
def nearest_into(
    p,
    ids,
    q,
    nrm,
    open_,
    planes,
    plane_c,
    tri,
    adjacent,
    paired,
    plane_id,
    origin,
    cell,
    shape,
    reach,
    start,
    faces,
    box32,
):
    """Closest points of p (n, 3) on a mesh into q (n, 3), their normals into ``nrm`` (n, 3); ``ids``
    (n,) holds a guess of each point's face (-1: none) and gets the answer. Returns how many points are
    ``open`` (n,) (set True for them, left as they were for the rest).

    A point keeps its guessed face when no other face can be nearer (it projects inside the face by more than 2|d|,
    :func:`_project`, or the faces of its plane around it hold the disc of that radius, :func:`_in_plane`); one that
    left it walks across the edges it left by (``adjacent``, :func:`_walk`) and takes the first face that keeps it.
    Otherwise the faces listed in the grid's cells (:func:`face_grid`) around the point's are searched exactly, ring
    after ring of cells out to ``reach`` rings: after each ring, every face nearer than the ring block's walls has
    been seen, so the search stops once its best is nearer than those, and is certain for an answer within ``reach``
    × ``cell`` (cells farther than the best so far are skipped whole: a face is listed in every cell it meets, so a
    nearer face has a nearer cell; faces whose plane or bounding box is farther than the best are skipped, first by
    ``box32`` (f, 6) float32, each face's box rounded outward (:func:`face_boxes`): it skips a subset of what the
    float64 box skips, which then still decides, so the faces searched are the same; the guessed face starts the
    search, which prunes more). A point the face found keeps gets its projection on the face's plane, like a followed point, so that the
    answer does not depend on the guess; a point closest to an edge or a corner gets the closest point of that face,
    in float64, and the direction from it to the point as its normal (:func:`edge_normal`; where faces tie exactly,
    at their common edge, the lowest face id takes the point, whatever the guess: the point and the normal are the
    same whichever face it is). Points left to the global search (outside the grid or farther than the reach from
    the surface) are marked in ``open``. The tests that keep a guess or a walked-to face trust a point to lie nearer
    its face than any face not adjacent to it (true near a part's surface; not for a point past the middle of a thin
    sheet, or in a slot narrower than twice its distance): the search's answer otherwise.
    """
    n = p.shape[0]
    margin = reach * cell
    m2 = margin * margin
    n_open = 0
    cc = np.empty(3, np.int64)
    seen = np.empty(_PATCH, np.int64)  # the plane test's faces, one buffer for every point
    for i in range(n):
        f = ids[i]
        if f >= 0:
            g = f
            if not _project(p, i, f, planes, plane_c, q)[0] and not _in_plane(
                p, i, f, planes, plane_c, tri, adjacent, paired, plane_id, q, seen
            ):
                g = _walk(p, i, f, planes, plane_c, tri, adjacent, paired, plane_id, q, seen)
            if g >= 0:
                ids[i] = g
                nrm[i, 0], nrm[i, 1], nrm[i, 2] = planes[g, 0, 0], planes[g, 0, 1], planes[g, 0, 2]
                continue
        outside = False
        for j in range(3):
            cc[j] = np.int64(np.floor((p[i, j] - origin[j]) / cell))
            if cc[j] < 0 or cc[j] >= shape[j]:
                outside = True
        if outside:
            open_[i] = True
            n_open += 1
            continue
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        best = m2
        g_best = -1
        bx, by, bz = 0.0, 0.0, 0.0
        if f < 0 and i > 0:  # no guess: the last point's face (a neighbour in a voxel-ordered cloud) seeds the search
            f = ids[i - 1]
        inset2 = -1.0  # squared: how far inside the best face p projects (-1: not inside)
        if f >= 0:  # a seed only prunes: every face near enough is still searched, ties go to the lowest id
            gx, gy, gz = _closest_on_triangle(px, py, pz, tri[f, 0], tri[f, 1], tri[f, 2])
            d2 = (px - gx) ** 2 + (py - gy) ** 2 + (pz - gz) ** 2
            if d2 <= best:
                best, g_best, bx, by, bz = d2, f, gx, gy, gz
                inset2 = _inset2(p, i, f, planes, plane_c)
        # how far the point lies inside its own cell from each wall: the ring blocks' walls are that plus r cells
        wall = np.inf
        for j in range(3):
            below = p[i, j] - (origin[j] + cc[j] * cell)
            wall = min(wall, below, cell - below)
        for r in range(reach + 1):
            for a in range(max(cc[0] - r, 0), min(cc[0] + r, shape[0] - 1) + 1):
                ga = _gap(px, origin[0] + a * cell, cell)
                for b in range(max(cc[1] - r, 0), min(cc[1] + r, shape[1] - 1) + 1):
                    gab = ga + _gap(py, origin[1] + b * cell, cell)
                    if gab > best * (1.0 + 1e-6) + 1e-22:  # the column's cells all lie farther than the best
                        continue
                    shell = abs(a - cc[0]) == r or abs(b - cc[1]) == r
                    step = 1 if shell else 2 * r
                    c = cc[2] - r
                    while c <= cc[2] + r:
                        # a cell farther than the best holds no nearer face: a face is listed in every cell it meets
                        if (
                            0 <= c < shape[2]
                            and gab + _gap(pz, origin[2] + c * cell, cell) <= best * (1.0 + 1e-6) + 1e-22
                        ):
                            cell_id = (a * shape[1] + b) * shape[2] + c
                            for e in range(start[cell_id], start[cell_id + 1]):
                                g = np.int64(faces[e])
                                gap2 = 0.0  # the float32 box first: a compact row, read where the float64 corners are three
                                for j in range(3):
                                    gap = max(box32[g, j] - p[i, j], p[i, j] - box32[g, j + 3], 0.0)
                                    gap2 += gap * gap
                                if gap2 > best:
                                    continue
                                if g == g_best or (
                                    planes[g, 0, 0] == 0.0 and planes[g, 0, 1] == 0.0 and planes[g, 0, 2] == 0.0
                                ):
                                    continue  # the best again; or a zero-area face (no normal), on its neighbours' edges: they answer for it
                                if plane_id[g] == plane_id[g_best] and inset2 > best * 1e-6 + 1e-18:
                                    continue  # in the plane of the best face, which p projects well inside of: farther by at least that inset
                                h = planes[g, 0, 0] * px + planes[g, 0, 1] * py + planes[g, 0, 2] * pz - plane_c[g, 0]
                                if (
                                    h * h > best * (1.0 + 1e-6) + 1e-22
                                ):  # its plane alone is farther (with room for rounding: no tie is lost)
                                    continue
                                box = 0.0  # after the plane: a long face's box holds the point more often than its plane passes near it
                                for j in range(3):
                                    lo_j = min(tri[g, 0, j], tri[g, 1, j], tri[g, 2, j])
                                    hi_j = max(tri[g, 0, j], tri[g, 1, j], tri[g, 2, j])
                                    gap = max(lo_j - p[i, j], p[i, j] - hi_j, 0.0)
                                    box += gap * gap
                                if box > best:
                                    continue
                                gx, gy, gz = _closest_on_triangle(px, py, pz, tri[g, 0], tri[g, 1], tri[g, 2])
                                d2 = (px - gx) ** 2 + (py - gy) ** 2 + (pz - gz) ** 2
                                if d2 < best or (d2 == best and (g_best < 0 or g < g_best)):
                                    best, g_best, bx, by, bz = d2, g, gx, gy, gz
                                    inset2 = _inset2(p, i, g, planes, plane_c)
                        c += step if step > 0 else 1
            reached = wall + r * cell  # every face nearer than this has been seen
            if g_best >= 0 and best < reached * reached:
                break
        if g_best < 0:
            open_[i] = True
            n_open += 1
            continue
        ids[i] = g_best
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = planes[g_best, 0, 0], planes[g_best, 0, 1], planes[g_best, 0, 2]
        well_inside, inside = _project(p, i, g_best, planes, plane_c, q)
        # near an edge, and not kept by the faces of its plane: the face's closest point
        if not well_inside and not _in_plane(p, i, g_best, planes, plane_c, tri, adjacent, paired, plane_id, q, seen):
            q[i, 0], q[i, 1], q[i, 2] = bx, by, bz
            if not inside and _crease(p, i, g_best, planes, plane_c, adjacent):
                edge_normal(p, i, q, nrm)
    return n_open


@njit(cache=True, nogil=True, inline="always")
def _crease(p, i, f, planes, plane_c, adjacent):
    """Whether p[i], outside face f, is closest to a crease: every edge of f it lies outside of has a face
    across it, and one of those faces turns by more than ``CREASE_DEG`` from f. There the faces tie and the
    normal must be the surface's own. On the mesh's rim (an open sheet's) only f is there, and its plane
    answers, as if the sheet went on; across a fainter fold (a finely tessellated curve) the faces'
    normals differ by less than the fold, and f's stands, as before."""
    sharp = False
    for k in range(3):
        hk = (
            planes[f, k + 1, 0] * p[i, 0]
            + planes[f, k + 1, 1] * p[i, 1]
            + planes[f, k + 1, 2] * p[i, 2]
            - plane_c[f, k + 1]
        )
        if hk < 0.0:
            g = adjacent[f, k]
            if g < 0:
                return False
            cos = (
                planes[f, 0, 0] * planes[g, 0, 0]
                + planes[f, 0, 1] * planes[g, 0, 1]
                + planes[f, 0, 2] * planes[g, 0, 2]
            )
            sharp = sharp or cos < _CREASE_COS
    return sharp


@njit(cache=True, nogil=True, inline="always")
def edge_normal(p, i, q, nrm):
    """Where p[i]'s closest point q[i] lies on an edge or a corner, the surface's own normal there: the
    direction from q[i] to p[i] (the distance's gradient), signed like the face normal in ``nrm[i]``.
    The faces that meet at that edge tie, and which of them answers depends on the triangulation; this
    direction does not. A point on the edge itself (no direction) keeps the face normal."""
    dx, dy, dz = p[i, 0] - q[i, 0], p[i, 1] - q[i, 1], p[i, 2] - q[i, 2]
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if d <= 1e-9:  # within a nanometre of the edge: the direction is rounding, and the point as good as on it
        return
    if dx * nrm[i, 0] + dy * nrm[i, 1] + dz * nrm[i, 2] < 0.0:
        d = -d
    nrm[i, 0], nrm[i, 1], nrm[i, 2] = dx / d, dy / d, dz / d
