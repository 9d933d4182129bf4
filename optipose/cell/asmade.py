"""The part as made: the CAD surface displaced along its normal by a field drawn per seed (docs/cell.md).

A manufacturing process leaves each face off its drawing in a few ways, each a term of the field:

- ``form``: a smooth random deviation (waviness, flatness), RMS ``form_rms`` over the surface, in
  wavelengths between ``form_wavelengths`` (a sum of random plane waves: directions uniform on the sphere,
  wavelengths log-uniform in the band, phases uniform; its RMS over space is ``form_rms``);
- ``face``: each plane face of the part off its drawing as a whole, by an offset (σ ``face_offset``) and a
  tilt about its centroid (σ ``face_tilt`` about each of two axes in the face): the size and angle
  tolerances of a milled face, or a bend angle of a sheet;
- ``scale``: a size error per axis of the part's frame (σ ``scale``, relative), about the part's centre:
  the residual shrinkage of a print;
- ``warp``: a bow of the part along z (its print's build direction), σ ``warp`` at the ends of its longest
  side, zero on average;
- ``layers``: the layer lines of a print on its side walls, a triangle wave of period ``layer_height``
  along z and peak-to-valley ``layer_amplitude`` (faces turning less than 60° from vertical).

Only the normal component of a displacement moves what a sensor measures (to first order in the
displacement over the surface's curvature radius), so the field is a normal offset ``d(x)`` (m, outward
positive) at part-frame points ``x`` on faces with outward normals ``n``. A part instance is a
deterministic function of its seed and the CAD surface, never of the triangles the surface is cut into:
every sensor and every orientation of a run sees the same part, and so does the same surface in other
triangles, in another order, or written in float32.

- The form waves, the scale, the warp and the layers' phase are drawn from the seed alone, a fixed number.
- A plane face of the part is found from the surface (:func:`optipose.model.planes.surface_planes`: faces
  whose planes agree, whatever their number and order, to the rounding of a float32 STL), and its centroid
  is its faces' area centroid. Its offset and tilt are a function of the plane itself: standard normals at
  its place in the space of planes — its unit normal in steps of ``_DRAW_NORMAL`` and its offset from the
  part's bounding-box centre in steps of ``_DRAW_OFFSET`` — from a lattice of normals hashed from the seed
  (:func:`optipose.cell.kernels.lattice_normals`). Planes more than two steps apart on some coordinate draw
  independently; the same plane computed from other triangles (its normal and centroid equal to rounding)
  draws the same to rounding, where a per-plane key rounded to a grid would jump at the grid's cells.
- A face of no area is on a plane that does not move.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from optipose.cell.kernels import lattice_normals
from optipose.model.planes import surface_planes

__all__ = ["Process", "AsMade", "FORM_MODES"]

FORM_MODES = 256  # plane waves in the form field; the RMS of one draw over a surface is within a few % of form_rms
_GRID_NODES = 2_000_000  # the form grid's nodes at most (a metre-long part gets a coarser grid)
_LAYER_WALL = 0.5  # |n_z| below this: a side wall, where a print's layer lines show
_DRAW_NORMAL = 2e-3  # rad: a plane's normal in these steps places its draws (facets of a 96-gon are 0.065 apart)
_DRAW_OFFSET = 5e-5  # m: and its offset in these


@dataclass(frozen=True)
class Process:
    """A manufacturing process's deviations from the CAD (SI: m, rad, relative). Zero everywhere: the CAD."""

    name: str = "cad"
    form_rms: float = 0.0
    form_wavelengths: tuple[float, float] = (0.01, 0.04)
    face_offset: float = 0.0
    face_tilt: float = 0.0
    scale: float = 0.0
    warp: float = 0.0
    layer_height: float = 0.0
    layer_amplitude: float = 0.0

    @property
    def exact(self) -> bool:
        """Whether this process makes the CAD exactly (the band and the layers' period are no magnitudes)."""
        return all(
            getattr(self, f.name) == 0
            for f in fields(self)
            if f.name not in ("name", "form_wavelengths", "layer_height")
        )

    def scaled(self, factor: float) -> "Process":
        """Every magnitude times ``factor`` (a better or a worse shop); wavelengths and layer height kept."""
        keep = ("name", "form_wavelengths", "layer_height")
        return Process(
            **{
                f.name: getattr(self, f.name) if f.name in keep else getattr(self, f.name) * factor
                for f in fields(self)
            }
        )


class AsMade:
    """One instance of a part as made by ``process``, drawn from ``seed``.

    vertices (v, 3) m, faces (f, 3): the CAD mesh in its own frame. ``plane`` (f,): each face's plane
    (:func:`optipose.model.planes.surface_planes`; a face of no area: the last, which does not move); faces
    of one plane are one face of the part and move together. ``plane_centroid`` (p, 3), ``plane_offset``
    (p,), ``plane_tilt`` (p, 3): per plane.
    """

    def __init__(self, process: Process, vertices: np.ndarray, faces: np.ndarray, seed: int):
        self.process = process
        rng = np.random.default_rng([int(seed), 0xA5AADE])
        p = process
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        self.centre, self.extent = 0.5 * (lo + hi), np.maximum(hi - lo, 1e-9)
        # form: random plane waves (drawn whatever the process, so a process's terms do not shift each other's draws)
        direction = rng.normal(size=(FORM_MODES, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        lam = np.exp(rng.uniform(*np.log(p.form_wavelengths), FORM_MODES))
        self.k = direction * (2 * np.pi / lam)[:, None]
        self.phase = rng.uniform(0, 2 * np.pi, FORM_MODES)
        self.form_amplitude = p.form_rms * np.sqrt(2.0 / FORM_MODES)
        pad = 1e-3 + 0.01 * np.max(
            hi - lo
        )  # the grid covers the part and a margin: an as-made point lies near its face
        self._lo, self._hi, self._grid = lo - pad, hi + pad, None
        self.scale = rng.normal(0.0, 1.0, 3) * p.scale
        self.warp = rng.normal() * p.warp
        self.layer_phase = rng.uniform(0.0, 1.0)
        key = np.uint64(rng.integers(1, 2**63))  # the planes' lattice
        # faces: offset and tilt of each plane about its centroid, drawn at the plane's place
        self.plane = np.zeros(len(faces), np.int64)
        self.plane_centroid, self.plane_offset, self.plane_tilt = np.zeros((1, 3)), np.zeros(1), np.zeros((1, 3))
        if p.face_offset or p.face_tilt:
            planes = surface_planes(vertices, faces)
            count = len(planes.area)
            self.plane = np.where(planes.plane < 0, count, planes.plane)
            draw = self.plane_draws(planes.normal, planes.centroid, key)
            self.plane_centroid = np.vstack([planes.centroid, np.zeros((1, 3))])
            self.plane_offset = np.r_[draw[:, 0] * p.face_offset, 0.0]
            self.plane_tilt = np.vstack([draw[:, 1:] * p.face_tilt, np.zeros((1, 3))])  # its part along n does nothing

    def plane_draws(self, normal: np.ndarray, centroid: np.ndarray, key: np.uint64) -> np.ndarray:
        """(p, 4) standard normals per plane (unit ``normal`` (p, 3), ``centroid`` (p, 3) m): its offset's and
        its tilt's, a function of where the plane lies (its normal, its offset from the part's centre)."""
        offset = np.einsum("ij,ij->i", normal, centroid - self.centre)
        place = np.ascontiguousarray(np.c_[normal / _DRAW_NORMAL, offset / _DRAW_OFFSET])
        return lattice_normals(place, key, 4)

    def offset(self, x: np.ndarray, n: np.ndarray, face: np.ndarray) -> np.ndarray:
        """The surface's normal offset (m, outward positive) at part-frame points ``x`` (m, 3) on faces
        ``face`` (m,) whose outward unit normals are ``n`` (m, 3). (The scans take it from the compiled
        :func:`optipose.cell.kernels.along_rays`, the form term from its grid.)"""
        p = self.process
        d = np.zeros(len(x))
        if p.form_rms:
            d += self.form_exact(x)  # the scans' kernel interpolates it on form_grid
        if p.face_offset or p.face_tilt:
            pl = self.plane[face]
            arm = x - self.plane_centroid[pl]
            d += self.plane_offset[pl] + np.einsum("ij,ij->i", np.cross(self.plane_tilt[pl], arm), n)
        if p.scale:
            d += np.einsum("ij,ij->i", (x - self.centre) * self.scale, n)
        if p.warp:
            long = int(np.argmax(self.extent[:2]))
            s = 2.0 * (x[:, long] - self.centre[long]) / self.extent[long]  # -1..1 along the longest side
            d += self.warp * (s**2 - 1.0 / 3.0) * n[:, 2]
        if p.layer_amplitude and p.layer_height:
            t = (x[:, 2] / p.layer_height + self.layer_phase) % 1.0
            wall = np.abs(n[:, 2]) < _LAYER_WALL
            d += np.where(wall, p.layer_amplitude * (np.abs(2.0 * t - 1.0) - 0.5), 0.0)
        return d

    def form_exact(self, x: np.ndarray) -> np.ndarray:
        """The smooth form deviation (m) at points ``x`` (m, 3), summed over every plane wave, in blocks."""
        out = np.empty(len(x))
        for i in range(0, len(x), 65536):
            out[i : i + 65536] = np.cos(x[i : i + 65536] @ self.k.T + self.phase) @ np.full(
                FORM_MODES, self.form_amplitude
            )
        return out

    def form_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The form field on a grid over the part and a margin, (nx, ny, nz) m, with its first node (3,) and
        spacing (3,) m: at most a tenth of the shortest wavelength apart (trilinear between them is within
        2 % of the field), coarser only past :data:`_GRID_NODES` nodes; (0, 0, 0) when there is no form term."""
        if self._grid is None:
            if not self.process.form_rms:
                self._grid = (np.zeros((0, 0, 0)), np.zeros(3), np.ones(3))
            else:
                h = max(
                    self.process.form_wavelengths[0] / 10.0,
                    float(np.prod(self._hi - self._lo) / _GRID_NODES) ** (1 / 3),
                )
                counts = [max(2, int(np.ceil((hi - lo) / h)) + 1) for lo, hi in zip(self._lo, self._hi)]
                axes = [np.linspace(lo, hi, c) for lo, hi, c in zip(self._lo, self._hi, counts)]
                step = np.array([a[1] - a[0] for a in axes])
                self._grid = (self._form_on(axes), self._lo.copy(), step)
        return self._grid

    def _form_on(self, axes: list[np.ndarray]) -> np.ndarray:
        """:meth:`form_exact` at the nodes of the grid ``axes`` (x, y, z node coordinates), (nx, ny, nz).
        A plane wave is a product over the axes, cos(k·x + φ) = Re e^{iφ} e^{i kx x} e^{i ky y} e^{i kz z}:
        a matrix product per block of x nodes instead of a cosine per node and wave (a cell instance's
        set-up, once per draw and worker)."""
        (x, y, z), k = axes, self.k
        wave = [np.exp(1j * np.multiply.outer(a, k[:, j])) for j, a in enumerate((x, y, z))]  # (n_axis, FORM_MODES)
        coefficient = self.form_amplitude * np.exp(1j * self.phase)
        out = np.empty((len(x), len(y), len(z)))
        block = max(1, 2**20 // (len(y) * FORM_MODES))
        for i in range(0, len(x), block):
            xy = (wave[0][i : i + block, None, :] * (wave[1] * coefficient)[None]).reshape(-1, FORM_MODES)
            out[i : i + block] = (xy @ wave[2].T).real.reshape(-1, len(y), len(z))
        return out

    def kernel_args(self) -> tuple:
        """The instance as :func:`optipose.cell.kernels.along_rays` takes it (from ``form`` to ``wall``)."""
        p = self.process
        faces = bool(p.face_offset or p.face_tilt)
        long = int(np.argmax(self.extent[:2]))
        return (
            *self.form_grid(),
            self.plane if faces else np.zeros(0, np.int64),
            self.plane_centroid,
            self.plane_offset,
            self.plane_tilt,
            self.scale,
            self.centre,
            float(self.warp),
            long,
            float(self.extent[long] / 2),
            float(p.layer_height or 1.0),
            float(p.layer_amplitude),
            float(self.layer_phase),
            _LAYER_WALL,
        )
