"""Compiled sums of the surrogate's cell term (numba, ``nogil``): one pass over a turn's voxel centroids adds
up every ΣJᵀ(·) that :func:`optipose.search.cell_terms.sensor_maps` keeps, instead of building the (m, F)
part columns, the (m, 6, 6) path products and a dozen numpy temporaries per turn. The arithmetic is
documented in :mod:`optipose.search.cell_terms` and :mod:`optipose.search.mounting`; compiled once per
machine and cached next to this file (``cache=True``; ``scripts/warm_kernels.py`` compiles it at set-up).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["turn_sums"]


# n! for the series' terms (floats: each a constant of the compiled code)
_F3, _F4, _F5, _F6, _F7, _F8, _F9, _F10, _F11, _F12, _F13, _F14 = (float(math.factorial(n)) for n in range(3, 15))


@njit(cache=True, nogil=True, inline="always")
def _cos_sin(phase):
    """cos and sin of a phase (rad), to ~1e-14: reduced to [−π, π], a Taylor series at a quarter of it and two
    doublings — plain arithmetic, so that a loop over phases vectorises (numba has no vector sin here)."""
    t = 0.25 * (phase - 2.0 * np.pi * math.floor(phase * (0.5 / np.pi) + 0.5))
    t2 = t * t
    s = t * (1.0 + t2 * (-1 / _F3 + t2 * (1 / _F5 + t2 * (-1 / _F7 + t2 * (1 / _F9 + t2 * (-1 / _F11 + t2 / _F13))))))
    c = 1.0 + t2 * (
        -0.5 + t2 * (1 / _F4 + t2 * (-1 / _F6 + t2 * (1 / _F8 + t2 * (-1 / _F10 + t2 * (1 / _F12 - t2 / _F14)))))
    )
    s, c = 2.0 * s * c, 1.0 - 2.0 * s * s
    return 1.0 - 2.0 * s * s, 2.0 * s * c


@njit(cache=True, nogil=True)
def turn_sums(
    v, n, plane, s, at, profiles, R, centre, T_O_S, fan, apex, k, made_centre, scale, long, extent, warp, pc, tilt
):
    """One turn's sums over its voxel centroids, about the rotation centre, in O.

    v, n : (m, 3) part-frame centroids and their unit CAD normals; plane : (m,) each one's plane number
    (``pc`` rows), or (0,) when the faces are not modelled; s : (m,) m the travel at which each was seen, at :
    (m,) the profile (of ``profiles``) that saw it; R : (3, 3) the part's turn; centre : (3,) m; T_O_S :
    (4, 4) the sensor's pose; fan : rays from ``apex`` (3,) m in O (else along z_S); k : (F, 3) rad/m the form field's frequencies, and
    made_centre (3,) m, scale, long (the longest axis), extent (m, along it), warp: the part columns' (none
    when F is 0: the CAD); pc : (planes, 3) m the plane centroids, tilt : the face tilt's σ (rad).

    With Jᵢ = [(pᵢ − c) × nᵢ, nᵢ] (pᵢ, nᵢ turned into O), Lᵢ the residual per unit head error
    (:func:`optipose.search.mounting.displacement`), sᵢ the travel it was seen at, cosᵢ its ray's cosine to nᵢ
    and gᵢ its part columns (form cos F, form sin F, scale 3, warp 1 — per unit σ of the form's amplitude,
    the scale and the warp), returns

    JJ (profiles, 6, 6) ΣJᵢJᵢᵀ per profile that saw the point; JL (6, 6) ΣJᵢLᵢᵀ; JG (6, 2F + 4 or 0) ΣJᵢgᵢᵀ;
    Js (6,) ΣJᵢ nᵢₓ sᵢ; white (6, 6) ΣJᵢJᵢᵀ cos²ᵢ; Jc (6,) ΣJᵢ cosᵢ; face (planes, 6, 4) per plane
    ΣJᵢ [1, tilt·(vᵢ − centroid) × nᵢ] (the face offset's σ not applied); seen (planes,) points per plane.
    """
    m, F = v.shape[0], k.shape[0]
    G = 2 * F + 4 if F else 0
    c0, c1, c2 = centre[0], centre[1], centre[2]
    o0, o1, o2 = T_O_S[0, 3], T_O_S[1, 3], T_O_S[2, 3]
    z0, z1, z2 = T_O_S[0, 2], T_O_S[1, 2], T_O_S[2, 2]
    JJ, JL, JG = np.zeros((profiles, 6, 6)), np.zeros((6, 6)), np.zeros((6, G))
    Js, white, Jc = np.zeros(6), np.zeros((6, 6)), np.zeros(6)
    face, seen = np.zeros((pc.shape[0], 6, 4)), np.zeros(pc.shape[0], np.int64)
    kx, ky, kz = k[:, 0].copy(), k[:, 1].copy(), k[:, 2].copy()
    J, L, g = np.empty(6), np.empty(6), np.empty(G)
    for i in range(m):
        d0, d1, d2 = v[i, 0] - c0, v[i, 1] - c1, v[i, 2] - c2
        q0 = R[0, 0] * d0 + R[0, 1] * d1 + R[0, 2] * d2  # p − c
        q1 = R[1, 0] * d0 + R[1, 1] * d1 + R[1, 2] * d2
        q2 = R[2, 0] * d0 + R[2, 1] * d1 + R[2, 2] * d2
        n0 = R[0, 0] * n[i, 0] + R[0, 1] * n[i, 1] + R[0, 2] * n[i, 2]
        n1 = R[1, 0] * n[i, 0] + R[1, 1] * n[i, 1] + R[1, 2] * n[i, 2]
        n2 = R[2, 0] * n[i, 0] + R[2, 1] * n[i, 1] + R[2, 2] * n[i, 2]
        J[0], J[1], J[2] = q1 * n2 - q2 * n1, q2 * n0 - q0 * n2, q0 * n1 - q1 * n0
        J[3], J[4], J[5] = n0, n1, n2
        p0, p1, p2 = q0 + c0, q1 + c1, q2 + c2
        a0, a1, a2 = p0 + s[i] - o0, p1 - o1, p2 - o2  # where the point was, less the head's origin
        w0, w1, w2 = n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0  # n × a: nᵀ[a]× as a column
        for b in range(3):
            L[b] = T_O_S[0, b] * w0 + T_O_S[1, b] * w1 + T_O_S[2, b] * w2
            L[3 + b] = -(T_O_S[0, b] * n0 + T_O_S[1, b] * n1 + T_O_S[2, b] * n2)
        if fan:
            u0, u1, u2 = p0 + s[i] - apex[0], p1 - apex[1], p2 - apex[2]
            cos = (u0 * n0 + u1 * n1 + u2 * n2) / math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        else:
            cos = z0 * n0 + z1 * n1 + z2 * n2
        for a in range(6):
            Ja = J[a]
            Js[a] += Ja * n0 * s[i]
            Jc[a] += Ja * cos
            for b in range(6):
                JJ[at[i], a, b] += Ja * J[b]
                JL[a, b] += Ja * L[b]
                white[a, b] += Ja * J[b] * (cos * cos)
        if F:
            x0, x1, x2 = v[i, 0], v[i, 1], v[i, 2]
            for f in range(F):
                g[f], g[F + f] = _cos_sin(x0 * kx[f] + x1 * ky[f] + x2 * kz[f])
            for j in range(3):
                g[2 * F + j] = (v[i, j] - made_centre[j]) * n[i, j] * scale
            r = 2.0 * (v[i, long] - made_centre[long]) / extent
            g[2 * F + 3] = warp * (r * r - 1.0 / 3.0) * n[i, 2]
            for a in range(6):
                Ja = J[a]
                for j in range(G):
                    JG[a, j] += Ja * g[j]
        if plane.shape[0]:
            e = plane[i]
            e0, e1, e2 = v[i, 0] - pc[e, 0], v[i, 1] - pc[e, 1], v[i, 2] - pc[e, 2]
            arm0 = (e1 * n[i, 2] - e2 * n[i, 1]) * tilt  # tilt τ turns the point's normal offset by τ·(arm × n)
            arm1 = (e2 * n[i, 0] - e0 * n[i, 2]) * tilt
            arm2 = (e0 * n[i, 1] - e1 * n[i, 0]) * tilt
            seen[e] += 1
            for a in range(6):
                face[e, a, 0] += J[a]
                face[e, a, 1] += J[a] * arm0
                face[e, a, 2] += J[a] * arm1
                face[e, a, 3] += J[a] * arm2
    return JJ, JL, JG, Js, white, Jc, face, seen
