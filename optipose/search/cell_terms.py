"""The surrogate's cell term: a real cell's error sources propagated to the rotation estimate, linearly
(docs/method.md, "The surrogate under the cell"; the sources in docs/cell.md).

Each source moves a voxel centroid i of a sensor's cloud off the CAD by a normal residual rᵢ, linear in the
source's random numbers η ~ N(0, I): r = X η. One point-to-plane Gauss–Newton step of a subset then settles on

    δ = −P Σ_j Jⱼᵀ rⱼ,   P = (Σ_j Aⱼ)⁻¹ (its rotation rows),   Aⱼ = Σ JᵀJ of sensor j's centroids,

so each source adds P Cov(ΣJᵀr) Pᵀ to the estimate's covariance, the algebra of
:mod:`optipose.search.mounting`. Per sensor pose and turn, :func:`sensor_maps` keeps ΣJᵀr per unit η of
every source (:class:`CellMaps`); a subset's covariance needs only sums of those, and the sources that two
sensors share (the same part, the same robot path, the same frame) are kept as shared columns so that
their errors add before they are squared. The sources:

* **calibration**: each head's own rigid error (σ per axis, independent between heads) and the frame's
  (one for every head, about the rotation centre, mapped into each head's frame); the point displacement is
  mounting.py's, a rigid motion plus the shear of a laser plane that met each point at another travel.
  Not zeroed (the cell's default), a rigid error is not cancelled: a head's rotation about its laser plane's
  normal turns its cloud and the estimate by as much. Zeroed (``[calibration] zeroed``), what the map is at
  the nominal orientation is taken off, as mounting.py does.
* **robot path**: the part's pose error (translation, rotation about the centre) at the travel where each
  point was seen, a Gauss–Markov process along the travel (correlation exp(−|Δs|/ℓ)): its covariance's
  leading eigenvectors on the travel's grid are the shared columns; the scan step's relative error is one
  more column. The set orientation's error is the protocol's ground truth's: it adds σ² to every axis of
  every layout alike (:attr:`CellMaps.orientation`), and does not rank.
* **part as made**: the form field (random plane waves in the process's wavelength band) as random Fourier
  features of its isotropic covariance (fixed frequencies, the band's spectrum); each plane face's offset
  and tilt (columns per plane, shared by the sensors that see it); the scale per axis and the warp.
* **material**: speckle, the sub-surface spread and spurious returns (their variance f·range²/3) as white
  noise along the rays, averaged over the raw points of a voxel; the sub-surface bias as a deterministic
  ΣJᵀr (points moved deeper along their rays), added to the voxel bias's step.

What it leaves out: what the voxels do with displaced points (a centroid moves with its points, to first
order); the layer lines of a print (a period under the voxel size, averaged out); multipath ghosts near
concave edges; the grazing cap on d / cos; ICP's re-matching and its later steps; that one cell instance
(the calibration, the part) is fixed per run where the surrogate takes the variance over instances; and the
per-turn re-scan, as the rest of the surrogate (turns are the nominal scan turned).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optipose.cell.ranges import middle, spread
from optipose.search.cell_sums import turn_sums
from optipose.search.mounting import scaled_solve

__all__ = ["CellMaps", "CellModel", "sensor_maps", "subset_terms"]

_FORM_FEATURES = 48  # random Fourier frequencies of the form field: its covariance within ~15 % (1/√48)
_PATH_MODES = 12  # Gauss–Markov eigenvectors kept along the travel (the rest hold little variance over a scan)
_FLOAT64 = (0, 1, 4, 5)  # A, own, white, bias: kept in float64 (CellMaps)
_MAX_STD = np.deg2rad(5.0)  # as the surrogate's weak prior: beyond it an error is not small
_INSTANCES = 8  # magnitude instances a cell of ranges is scored on (optipose.cell.ranges.spread)
# the magnitudes a source's variance scales with (as their square), in the order of CellModel.magnitudes' columns;
# the path's correlation length changes the modes themselves and is kept at its range's middle
GROUPS = (
    "calibration.sensor_rotation",
    "calibration.sensor_translation",
    "calibration.frame_rotation",
    "calibration.frame_translation",
    "process_scale",
    "robot.path_rotation",
    "robot.path",
    "robot.step",
    "robot.orientation",
)


@dataclass(frozen=True)
class CellMaps:
    """One sensor pose's ΣJᵀr per unit random number of each source, per turn (index 0 the nominal
    orientation), in O about the rotation centre; the wide maps (``shared``, ``path``, ``faces``) float32 (a
    search caches one per pose), the 6 × 6 ones and the bias float64 (a subset's variance is a difference of
    their products: in float32 a last bit moved part C's surrogate score by 10 %).

    A : (turns + 1, 6, 6) ΣJᵀJ of the voxel centroids.
    own : (turns + 1, 6, 6) the head's own calibration error (independent between heads).
    shared : (turns + 1, 6, F) the sources every sensor of a subset shares per cell instance: the frame's
        calibration, the form field, the scale and the warp.
    path : (turns + 1, 6, Q) the robot path's modes and the step error (shared, one draw per scan).
    planes, faces : (p,) the part's plane numbers the centroids lie on, (turns + 1, p, 6, 4) each plane's
        offset and tilt (shared by the sensors that see the plane).
    white : (turns + 1, 6, 6) Cov(ΣJᵀr) of the material's white noise (independent between heads).
    bias : (turns + 1, 6) ΣJᵀr of the material's sub-surface bias (deterministic).
    orientation : rad, σ of the set orientation's error; zeroed : the cell is zeroed on a master scan.
    magnitudes : (instances, len(GROUPS)) each source group's variance factor per magnitude instance (the
        squared ratio of its magnitude to the middle the maps were built at): one row of ones for a cell of
        points, the model's :attr:`CellModel.magnitudes` (shared, not copied) for a cell of ranges.
    """

    A: np.ndarray
    own: np.ndarray
    shared: np.ndarray
    path: np.ndarray
    planes: np.ndarray
    faces: np.ndarray
    white: np.ndarray
    bias: np.ndarray
    orientation: float
    zeroed: bool
    magnitudes: np.ndarray = field(default_factory=lambda: np.ones((1, len(GROUPS))), repr=False)


class CellModel:
    """What :func:`sensor_maps` needs of a cell and a part, built once per surrogate.

    setup : :class:`optipose.cell.scans.CellSetup` (the cell, the part's process, the material's effects).
    vertices, faces : the part's mesh (m); centre : (3,) m, the rotation centre; offsets : (profiles,) m,
    the scan's travel at each profile (:meth:`optipose.model.motion.ScanMotion.offsets`); apex_z : m, the
    laser's apex on the sensor's z (inf: parallel rays).
    """

    def __init__(
        self, setup, vertices: np.ndarray, faces: np.ndarray, centre: np.ndarray, offsets: np.ndarray, apex_z: float
    ):
        from optipose.cell.asmade import AsMade

        ranges = setup.cell.ranges
        setup = setup.middle()  # the maps at the ranges' middles; each instance rescales their variances
        self.magnitudes = _magnitudes(ranges)
        cell, p, e = setup.cell, setup.process, setup.effects
        self.cell, self.process, self.centre, self.apex_z = cell, p, np.asarray(centre, float), float(apex_z)
        c = cell.calibration
        self.own_sigma = np.repeat([c.sensor_rotation, c.sensor_translation], 3)
        self.frame_sigma = np.repeat([c.frame_rotation, c.frame_translation], 3)
        r = cell.robot
        self.path_sigma = np.repeat([r.path_rotation, r.path], 3)
        self.offsets = np.ascontiguousarray(offsets, float)
        self.modes = (
            _gauss_markov_modes(self.offsets, r.path_correlation)
            if r.path or r.path_rotation
            else np.zeros((len(offsets), 0))
        )
        self.step = r.step
        self.white = e.speckle**2 + e.subsurface_sigma**2 + e.spurious_fraction * e.spurious_range**2 / 3
        self.sub_bias = e.subsurface_bias
        self.made = None
        if not p.exact:
            self.made = AsMade(
                p, vertices, faces, 0
            )  # its planes, their centroids, centre and extent (no draw is used)
            self.plane = self.made.plane
            rng = np.random.default_rng(2022_1536)  # fixed: a pose always scores the same
            d = rng.normal(size=(_FORM_FEATURES, 3))
            lam = np.exp(rng.uniform(*np.log(p.form_wavelengths), _FORM_FEATURES))
            self.k = d / np.linalg.norm(d, axis=1, keepdims=True) * (2 * np.pi / lam)[:, None]
        # what the compiled pass needs besides a turn's points, fixed per model (the CAD: no part columns)
        form = p.form_rms / np.sqrt(_FORM_FEATURES)
        self.part_scale = np.r_[np.full(2 * _FORM_FEATURES, form), np.ones(4)] if self.made is not None else np.zeros(0)
        made = self.made
        long = 0 if made is None else int(np.argmax(made.extent[:2]))
        self._part_args = (
            (np.zeros((0, 3)), np.zeros(3), 0.0, 0, 1.0, 0.0)
            if made is None
            else (self.k, np.asarray(made.centre, float), float(p.scale), long, float(made.extent[long]), float(p.warp))
        )
        self._face_args = (
            (np.ascontiguousarray(made.plane_centroid, float), float(p.face_tilt))
            if self.face_width
            else (np.zeros((0, 3)), 0.0)
        )

    def kernel_args(self, T_O_S: np.ndarray, v: np.ndarray, n: np.ndarray, face: np.ndarray, R: np.ndarray) -> tuple:
        """:func:`optipose.search.cell_sums.turn_sums`'s arguments for one turn (v, n (m, 3), face (m,), R (3, 3)),
        of one type each, so that it compiles once."""
        T = np.ascontiguousarray(T_O_S, float)
        fan = bool(np.isfinite(self.apex_z))
        apex = T[:3, 2] * self.apex_z + T[:3, 3] if fan else np.zeros(3)
        plane = self.plane[face] if self.face_width else np.zeros(0, np.int64)
        # the travel and the profile in numpy, as before: a point seen by one profile lies on its travel, where
        # the profile it is given turns on the last bit of s
        s = _travel((v - self.centre) @ R.T + self.centre, T)
        at = np.clip(np.searchsorted(self.offsets, s), 0, len(self.offsets) - 1)
        v, n, R = (np.ascontiguousarray(a, np.float64) for a in (v, n, R))
        plane, at = np.ascontiguousarray(plane, np.int64), at.astype(np.int64)
        return (v, n, plane, s, at, len(self.offsets), R, self.centre, T, fan, apex, *self._part_args, *self._face_args)

    def part_columns(self, x: np.ndarray, n: np.ndarray) -> np.ndarray:
        """(m, F) the normal offset at part-frame points x (m, 3), outward normals n, per unit random number of
        the form field's features, the scale per axis and the warp (F = 0 for the CAD): the columns
        :func:`optipose.search.cell_sums.turn_sums` sums without building them (tests check it does)."""
        if self.made is None:
            return np.zeros((len(x), 0))
        p, made = self.process, self.made
        # cos and sin in float32, as the maps are kept (in float64 they were three quarters of a pose's cell
        # term): the phase reduced to [−π, π] first, in float64, so that the cast loses ~1e-7 rad, not |phase|·1e-7
        phase = x @ self.k.T
        phase -= 2 * np.pi * np.round(phase * (0.5 / np.pi))
        phase = phase.astype(np.float32)
        form = p.form_rms / np.sqrt(_FORM_FEATURES) * np.hstack([np.cos(phase), np.sin(phase)], dtype=np.float64)
        scale = (x - made.centre) * n * p.scale
        long = int(np.argmax(made.extent[:2]))
        s = 2.0 * (x[:, long] - made.centre[long]) / made.extent[long]
        warp = (p.warp * (s**2 - 1.0 / 3.0) * n[:, 2])[:, None]
        return np.hstack([form, scale, warp])

    @property
    def face_width(self) -> int:
        """Random numbers per plane face: its offset and tilt (4), or none when the process moves no face."""
        p = self.process
        return 4 if self.made is not None and (p.face_offset or p.face_tilt) else 0


def _magnitudes(ranges) -> np.ndarray:
    """(instances, len(GROUPS)) the variance factor of each source group in each instance of the ranges'
    spread, relative to the ranges' middles; one row of ones without ranges."""
    if not ranges:
        return np.ones((1, len(GROUPS)))
    mid = {name: middle(low, high) for name, low, high in ranges}
    rows = [[(inst[g] / mid[g]) ** 2 if g in inst else 1.0 for g in GROUPS] for inst in spread(ranges, _INSTANCES)]
    return np.array(rows)


def _gauss_markov_modes(s: np.ndarray, length: float) -> np.ndarray:
    """(profiles, q): the leading eigenvectors of exp(−|Δs|/length) on the travel s, times √eigenvalue."""
    w, V = np.linalg.eigh(np.exp(-np.abs(s[:, None] - s[None, :]) / length))
    keep = np.argsort(w)[::-1][:_PATH_MODES]
    return V[:, keep] * np.sqrt(np.clip(w[keep], 0.0, None))


def sensor_maps(model: CellModel, turns: list[tuple], T_O_S: np.ndarray, raw_per_voxel: float) -> CellMaps:
    """One sensor pose's :class:`CellMaps` from its voxel centroids at each turn.

    turns : per turn (nominal first), (v (m, 3) part-frame centroids, n (m, 3) their CAD normals, face (m,)
    their faces, R (3, 3) the part's turn); T_O_S : the sensor's pose; raw_per_voxel : raw points a
    full-fidelity scan puts in a voxel, on average (the white noise averages down over them).
    """
    parts = [_turn_maps(model, T_O_S, raw_per_voxel, *t) for t in turns]
    planes = np.unique(np.concatenate([p[6] for p in parts]))
    faces = np.zeros((len(turns), len(planes), 6, model.face_width), np.float32)
    for m, p in enumerate(parts):
        if len(p[6]):
            faces[m, np.searchsorted(planes, p[6])] = p[7]
    c = model.cell
    kept = [np.array([p[i] for p in parts], np.float64 if i in _FLOAT64 else np.float32) for i in range(6)]
    return CellMaps(*kept[:4], planes, faces, *kept[4:], c.robot.orientation, c.calibration.zeroed, model.magnitudes)


def _turn_maps(model: CellModel, T_O_S: np.ndarray, raw_per_voxel: float, v, n, face, R) -> tuple:
    """One turn's maps: A, own, shared, path, white, bias, the planes seen and their (p, 6, 4) maps."""
    JJ, JL, JG, Js, white, Jc, per_plane, seen = turn_sums(*model.kernel_args(T_O_S, v, n, face, R))
    Rs, o = T_O_S[:3, :3], T_O_S[:3, 3]
    frame = np.zeros(
        (6, 6)
    )  # the frame's error (ω, t about the centre) as this head's own: r = Rsᵀω, t = Rsᵀ(ω × (o − c) + t_F)
    frame[:3, :3], frame[3:, 3:] = Rs.T, Rs.T
    frame[3:, :3] = -Rs.T @ _cross(o - model.centre)
    shared = np.hstack([JL @ frame * model.frame_sigma, JG * model.part_scale])
    path = np.zeros((6, 0))
    if model.modes.shape[1]:  # Σ_m modes ⊗ JJ: a point's pose error ξ(s) at the travel s of the profile that saw it
        path = np.einsum("pq,pab->aqb", model.modes, JJ * model.path_sigma).reshape(6, -1)
    if model.step:
        path = np.hstack([path, (Js * model.step)[:, None]])
    planes = np.flatnonzero(seen) if model.face_width else np.zeros(0, np.int64)
    per_plane = (
        per_plane[planes] * [model.process.face_offset, 1.0, 1.0, 1.0]
        if len(planes)
        else np.zeros((0, 6, model.face_width))
    )
    white = white * (model.white / max(raw_per_voxel, 1.0))
    return JJ.sum(axis=0), JL * model.own_sigma, shared, path, white, Jc * model.sub_bias, planes, per_plane


def _cross(a: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])


def _travel(p: np.ndarray, T_O_S: np.ndarray) -> np.ndarray:
    """(m,) m: the travel at which the laser plane met each point p (m, 3) in O (as mounting.displacement)."""
    y_S = T_O_S[:3, 1]
    across = float(y_S[0])
    return (T_O_S[:3, 3] - p) @ y_S / np.copysign(max(abs(across), 1e-3), across)


def subset_terms(maps: list[CellMaps]) -> tuple[np.ndarray, np.ndarray]:
    """A subset's variance (turns, 3) rad² of its rotation estimate from the cell's random sources, and the
    bias (turns, 3) rad the material's sub-surface bias adds to it. Zeroed: what a source fixed per cell
    instance does at the nominal orientation is taken off; a per-scan one (the path, the white noise, the
    set orientation) adds the master scan's own draw. Under a cell of ranges (maps whose ``magnitudes`` have
    more than one row) the variance is per magnitude instance: (instances, turns, 3)."""
    A = sum(m.A.astype(float) for m in maps)
    P = scaled_solve(A, np.broadcast_to(np.eye(6), A.shape))[:, :3]  # (turns + 1, 3, 6)
    planes = np.unique(np.concatenate([m.planes for m in maps]))
    faces = np.zeros((len(A), len(planes), 6, maps[0].faces.shape[3]))
    for m in maps:
        faces[:, np.searchsorted(planes, m.planes)] += m.faces
    fixed = np.concatenate(
        [*(m.own for m in maps), sum(m.shared for m in maps), faces.transpose(0, 2, 1, 3).reshape(len(A), 6, -1)],
        axis=2,
    ).astype(float)
    per_scan = sum(m.path for m in maps).astype(float)
    white = sum(m.white for m in maps).astype(float)
    bias = -np.einsum("tij,tj->ti", P, sum(m.bias for m in maps).astype(float))
    if len(maps[0].magnitudes) > 1:
        return _instance_variances(maps, P, faces, per_scan, white), (bias - bias[:1] if maps[0].zeroed else bias)[1:]
    PF = P @ fixed
    scan_var = (P @ per_scan) ** 2
    var = scan_var.sum(axis=2) + np.einsum("tij,tjk,tik->ti", P, white, P) + maps[0].orientation ** 2
    if maps[0].zeroed:
        PF, bias = PF - PF[:1], bias - bias[:1]
        var = var + var[:1]
    var = var + (PF**2).sum(axis=2)
    # float32 maps in a direction no point pins down can round to a small negative variance: none
    return np.clip(var[1:], 0.0, _MAX_STD**2), bias[1:]


def _instance_variances(maps: list[CellMaps], P, faces, per_scan, white) -> np.ndarray:
    """(instances, turns, 3) rad²: :func:`subset_terms`' variance with each source group's part (GROUPS) scaled
    by its factor in each magnitude instance (``maps[0].magnitudes``); the material's white noise as it is."""
    own = [P @ m.own.astype(float) for m in maps]
    shared = P @ sum(m.shared for m in maps).astype(float)
    fixed = (  # per group, P times its columns: sources fixed per cell instance
        np.concatenate([o[:, :, :3] for o in own], axis=2),
        np.concatenate([o[:, :, 3:] for o in own], axis=2),
        shared[:, :, :3],
        shared[:, :, 3:6],
        np.concatenate([shared[:, :, 6:], P @ faces.transpose(0, 2, 1, 3).reshape(len(P), 6, -1)], axis=2),
    )
    PS = P @ per_scan
    step = PS.shape[2] % 6 == 1  # the path's modes come in sixes (rotation, then translation); the step is one more
    column = np.arange(PS.shape[2] - step) % 6
    V = np.zeros((len(GROUPS), *PS.shape[:2]))
    modes = PS[:, :, : len(column)] ** 2
    V[5], V[6] = modes[:, :, column < 3].sum(axis=2), modes[:, :, column >= 3].sum(axis=2)
    if step:
        V[7] = PS[:, :, -1] ** 2
    V[8] = maps[0].orientation ** 2
    rest = np.einsum("tij,tjk,tik->ti", P, white, P)
    zeroed = maps[0].zeroed
    if zeroed:  # per scan: the master scan's own draw adds
        V, rest = V + V[:, :1], rest + rest[:1]
    for g, F in enumerate(fixed):
        F = F - F[:1] if zeroed else F
        V[g] += (F**2).sum(axis=2)
    var = rest[None] + np.einsum("kg,gti->kti", maps[0].magnitudes, V)
    return np.clip(var[:, 1:], 0.0, _MAX_STD**2)
