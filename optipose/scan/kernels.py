"""Compiled per-hit kernels of the scanner (numba, ``nogil`` so scanner threads run them in parallel).

Each kernel is one pass over a block's rays doing what would otherwise be some forty numpy passes; the
arithmetic is the scanner's, documented in :mod:`optipose.scan.scanner`. Compiled once per machine and cached
next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from optipose.scan.heights import place


@njit(cache=True, nogil=True)
def measure_hits(
    tri,
    n_part,
    n_col,
    shift_b,
    ray_cos,
    ray_sin,
    normals,
    offsets,
    frame,
    on_hull,
    apex_z,
    z_near,
    z_far,
    intensity_grid,
    threshold,
    saturation,
):
    """From Embree's first triangles (m,) of a block of rays to the hits that are measured; triangles
    ``n_part`` and above belong to occluders and hide what is behind them.

    Returns ``idx`` (n,) ray index in the block, ``T`` (n,) float64 distance from the fan's apex,
    ``intensity`` (n,), ``tri`` (n,) and ``shadow_test`` (n,) bool: hits whose shadow must still be
    traced (off the convex hull). A hit is kept when it faces the laser, lies in the Z range, clears
    the intensity threshold (and saturation, when > 0) and has the receiver in front of its face.
    A hit face's scalars come from its normal and offset and the sensor's ``frame`` (:func:`face_terms`).
    """
    m = tri.shape[0]
    out_idx = np.empty(m, np.int32)
    out_T = np.empty(m, np.float64)
    out_int = np.empty(m, np.float64)
    out_tri = np.empty(m, np.int32)
    out_shadow = np.empty(m, np.bool_)
    n_grid = intensity_grid.shape[0] - 1
    n = 0
    for i in range(m):
        f = tri[i]
        if f < 0 or f >= n_part:  # a miss, or an occluder (faces from n_part on): nothing measured
            continue
        k = i // n_col
        col = i - k * n_col
        shift = shift_b[k]
        c = ray_cos[col]
        nu, nw, q, b, a = face_terms(normals, offsets, frame, f)
        den = c * nu + ray_sin[col] * nw  # n·d = -cos(AoI)
        if den >= 0.0:
            continue
        T = (q + shift * b) / den
        z = apex_z + T * c
        if z < z_near or z > z_far:
            continue
        if a - shift * b <= 0.0:  # the receiver is behind the face
            continue
        x = -den * n_grid
        j = min(int(x), n_grid - 1)
        inten = intensity_grid[j] + (x - j) * (intensity_grid[j + 1] - intensity_grid[j])
        if inten < threshold or (saturation > 0.0 and inten > saturation):
            continue
        out_idx[n] = i
        out_T[n] = T
        out_int[n] = inten
        out_tri[n] = f
        out_shadow[n] = not on_hull[f]
        n += 1
    return out_idx[:n], out_T[:n], out_int[:n], out_tri[:n], out_shadow[:n]


@njit(cache=True, nogil=True)
def fill_columns(anchor_tri, cols, n_col, plane, shift_b, ray_cos, ray_sin, normals, offsets, frame, d, edge_n, edge_c):
    """The first triangles of a block's rays (m·n_col,) from those of its anchor columns (m, a) only.

    cols : (a,) the anchor columns, increasing, the first and last column among them. Between two
    neighbouring anchors of a profile that hit the same triangle (or both miss), every ray hits that
    triangle too: the rays lie in the laser plane between the two, so their hits lie on the segment
    between the anchors' hits, inside the (convex) triangle; only a feature thinner than the anchors'
    spacing could stand in between. When the two anchors hit two triangles of one plane (``plane``
    (f,): faces in one plane share a number, :func:`optipose.model.planes.shared_planes`), the rays
    between meet that plane on the same segment, and a ray whose point there lies inside either
    triangle hits it, for the same reason; the rest (a gap or a third triangle between) are cast.
    For the point: a ray of column c at shift s meets face f's plane ``T = (q_f + s·b_f)/(cos_c·nu_f +
    sin_c·nw_f)`` from the apex (:func:`face_terms`), at ``apex + T·d_c − s·step`` (part frame); it lies inside f when it is
    on the inner side of f's three edge planes (``edge_n`` (f, 3, 3), ``edge_c`` (f, 3)).
    Returns the filled triangles and ``need`` (n,), the rays that must be cast.
    """
    m, a = anchor_tri.shape
    tri = np.empty(m * n_col, anchor_tri.dtype)
    need = np.empty(m * n_col, np.int64)
    n = 0
    for k in range(m):
        base = k * n_col
        s = shift_b[k]
        for j in range(a):
            tri[base + cols[j]] = anchor_tri[k, j]
        for j in range(a - 1):
            t0 = anchor_tri[k, j]
            t1 = anchor_tri[k, j + 1]
            same = t0 == t1
            coplanar = (not same) and t0 >= 0 and t1 >= 0 and plane[t0] == plane[t1]
            for c in range(cols[j] + 1, cols[j + 1]):
                if same:
                    tri[base + c] = t0
                    continue
                if coplanar:
                    nu, nw, q, b, _ = face_terms(normals, offsets, frame, t0)
                    den = ray_cos[c] * nu + ray_sin[c] * nw
                    if den != 0.0:
                        T = (q + s * b) / den
                        p0 = frame[2, 0] + T * d[c, 0] - s * frame[3, 0]
                        p1 = frame[2, 1] + T * d[c, 1] - s * frame[3, 1]
                        p2 = frame[2, 2] + T * d[c, 2] - s * frame[3, 2]
                        if _inside(edge_n, edge_c, t0, p0, p1, p2):
                            tri[base + c] = t0
                            continue
                        if _inside(edge_n, edge_c, t1, p0, p1, p2):
                            tri[base + c] = t1
                            continue
                need[n] = base + c
                n += 1
    return tri, need[:n]


@njit(cache=True, nogil=True, inline="always")
def face_terms(normals, offsets, frame, f):
    """Face f's scalars for one sensor view, from its unit normal n and plane offset (n·x = offset) and the
    view's ``frame`` (5, 3): the fan's axis u, the line's direction w, the apex, the part's step and the
    receiver, in the part's frame at shift 0. Returns ``nu = n·u``, ``nw = n·w``, ``q = offset − n·apex``,
    ``b = n·step`` and ``a = n·receiver − offset``: formed per hit, so a scan costs nothing per face it misses."""
    n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
    nu = n0 * frame[0, 0] + n1 * frame[0, 1] + n2 * frame[0, 2]
    nw = n0 * frame[1, 0] + n1 * frame[1, 1] + n2 * frame[1, 2]
    q = offsets[f] - (n0 * frame[2, 0] + n1 * frame[2, 1] + n2 * frame[2, 2])
    b = n0 * frame[3, 0] + n1 * frame[3, 1] + n2 * frame[3, 2]
    a = n0 * frame[4, 0] + n1 * frame[4, 1] + n2 * frame[4, 2] - offsets[f]
    return nu, nw, q, b, a


@njit(cache=True, nogil=True, inline="always")
def _inside(edge_n, edge_c, f, p0, p1, p2):
    """Whether the point (on face f's plane) lies inside face f (its edges included)."""
    for e in range(3):
        if edge_n[f, e, 0] * p0 + edge_n[f, e, 1] * p1 + edge_n[f, e, 2] * p2 < edge_c[f, e]:
            return False
    return True


@njit(cache=True, nogil=True)
def split_at_anchors(idx, test, n_col, stride):
    """The hits ``test`` (positions in a block's hits, whose rays are ``idx``) on anchor columns, and the rest."""
    first = np.empty(test.shape[0], np.int64)
    rest = np.empty(test.shape[0], np.int64)
    a = 0
    b = 0
    for t in test:
        col = idx[t] % n_col
        if col % stride == 0 or col == n_col - 1:
            first[a] = t
            a += 1
        else:
            rest[b] = t
            b += 1
    return first[:a], rest[:b]


@njit(cache=True, nogil=True)
def unsure_between_anchors(idx, tri, keep, rest, ray_tri, n_col, stride, plane):
    """Of the hits ``rest`` (between anchors), those whose two anchors are not both measured, seen by
    the receiver (``keep``) and on the hit's own plane (``plane`` (f,), see :func:`fill_columns`): their
    shadow rays must still be traced."""
    seen = np.zeros(ray_tri.shape[0], np.bool_)
    for h in range(idx.shape[0]):
        if keep[h]:
            seen[idx[h]] = True
    out = np.empty(rest.shape[0], np.int64)
    n = 0
    for t in rest:
        ray = idx[t]
        col = ray % n_col
        left = ray - col % stride
        right = min(left + stride, ray - col + n_col - 1)
        f = tri[t]
        if not (seen[left] and seen[right] and plane[ray_tri[left]] == plane[f] and plane[ray_tri[right]] == plane[f]):
            out[n] = t
            n += 1
    return out[:n]


# Standard normal quantiles at the centres of 2^16 equal-probability cells: a draw is the inverse CDF of a
# uniform, interpolated between neighbouring quantiles (tails end at ±4.3σ, where a 2 µm σ is 9 µm).
_N_CELLS = 1 << 16
_QUANTILES = np.sqrt(2.0) * __import__("scipy.special", fromlist=["erfinv"]).erfinv(
    2.0 * (np.arange(_N_CELLS) + 0.5) / _N_CELLS - 1.0
)
# per cell: its quantile and the differences to the next and from the previous one (0 at the ends), in
# one row, so a draw reads one cache line
NORMAL_QUANTILES = np.ascontiguousarray(
    np.stack(
        [
            _QUANTILES,
            np.r_[_QUANTILES[1:], _QUANTILES[-1]] - _QUANTILES,
            _QUANTILES - np.r_[_QUANTILES[0], _QUANTILES[:-1]],
            np.zeros(_N_CELLS),
        ],
        axis=1,
    )
)


@njit(cache=True, nogil=True, inline="always")
def _normal(key, table):
    """A standard normal draw from a 64-bit key: splitmix64 → a uniform → inverse CDF by table
    (:data:`NORMAL_QUANTILES`). Counter-based, so a point's noise depends only on (seed, sensor, ray),
    never on threads or block order."""
    z = key + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    cell = np.int64(z >> np.uint64(48))  # top 16 bits: the cell
    frac = np.float64((z >> np.uint64(16)) & np.uint64(0xFFFF)) * (1.0 / 65536.0) - 0.5  # position in it
    side = 1 if frac >= 0.0 else 2  # toward the next quantile, or from the previous one
    return table[cell, 0] + frac * table[cell, side]


@njit(cache=True, nogil=True)
def write_points(
    idx,
    T,
    intensity,
    noise_key,
    table,
    n_col,
    k0,
    shift_b,
    ray_cos,
    x0,
    slope,
    apex_z,
    noise_sigma,
    threshold,
    z_resolution,
    R,
    t,
    raw,
    points,
    profile,
    column,
):
    """Noise along the ray, quantisation, the device's raw heights and the points in O, in one pass.

    noise_key : uint64 key of this sensor and scan (0 = exact points, no noise, no quantisation); a
    point's draw is keyed by it and the point's global ray index. table : :data:`NORMAL_QUANTILES`. Writes ``raw`` (the block's rows, flat,
    mm; empty: not written), and ``points`` (n, 3), ``profile`` (n,), ``column`` (n,) — the block's slices.
    """
    noisy = noise_key != 0
    with_raw = raw.shape[0] > 0
    base = np.uint64(k0 * n_col)
    m = idx.shape[0]
    scale = np.empty(m, np.float64)  # each point's noise along z_S, in a pass of its own (no branch, no gather of rays)
    if noisy:
        key = noise_key * np.uint64(0x100000001B3)
        for h in range(m):
            inten = min(max(intensity[h], threshold), 1.0)
            scale[h] = _normal(key ^ (base + np.uint64(idx[h])), table) * (noise_sigma / np.sqrt(inten))
    k, row = 0, 0  # the profile of ray i and its first ray: idx ascends, so they are followed, not divided out
    for h in range(m):
        i = idx[h]
        while i >= row + n_col:
            k += 1
            row += n_col
        col = i - row
        c = ray_cos[col]
        z = apex_z + T[h] * c
        if noisy:
            z += scale[h] * c  # along the ray, seen in z_S
            if z_resolution > 0.0:
                z = np.floor(z / z_resolution + 0.5) * z_resolution
        height = -1e3 * z  # the device's Z (mm); the point is what it gives, as a reader of the profile gets it
        if with_raw:
            raw[i] = height
        place(height, col, shift_b[k], x0, slope, R, t, points, h)
        profile[h] = k0 + k
        column[h] = col


@njit(cache=True, nogil=True)
def block_rays(rays, n_col, shift_b, o_P32, d_P32, step_P, t_max):
    """Embree's input for rays (n,) of a block (profile in the block × ``n_col`` + column): float32 origins
    (n, 3) on the window line moved back by the profile's shift (m) along ``step_P``, directions (n, 3)
    and far limits (n,) — what ``o_P32[col] - float32(shift · step_P)`` etc. give in numpy, in one pass."""
    n = rays.shape[0]
    o = np.empty((n, 3), np.float32)
    d = np.empty((n, 3), np.float32)
    t = np.empty(n, np.float32)
    for i in range(n):
        k = rays[i] // n_col
        col = rays[i] - k * n_col
        for j in range(3):
            o[i, j] = o_P32[col, j] - np.float32(shift_b[k] * step_P[j])
            d[i, j] = d_P32[col, j]
        t[i] = t_max[col]
    return o, d, t


@njit(cache=True, nogil=True)
def shadow_rays(T, col, shift, tri, apex_P, d_P, step_P, receiver_P, normals, offset):
    """Shadow rays of hits (n,): from each hit (``T`` along ray ``col`` of the profile at ``shift``, m),
    lifted ``offset`` off its face ``tri`` along the normal, to the receiver; float32 starts and
    directions (n, 3) for Embree, each from the float64 arithmetic the numpy form does, in its order."""
    n = T.shape[0]
    start = np.empty((n, 3), np.float32)
    direction = np.empty((n, 3), np.float32)
    for i in range(n):
        for j in range(3):
            step = shift[i] * step_P[j]
            s = apex_P[j] + T[i] * d_P[col[i], j] - step + offset * normals[tri[i], j]
            start[i, j] = s
            direction[i, j] = (receiver_P[j] - step) - s
    return start, direction
