"""One sensor as the scanner casts it: :class:`SensorView`, its fan and receiver in the part's frame, and
the float32 rays of a block of profiles that Embree casts (:mod:`optipose.scan.scanner`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.scan.kernels import block_rays

__all__ = ["SensorView"]


@dataclass(frozen=True)
class SensorView:
    """One sensor's fan and receiver in the part's frame at shift 0.

    ``frame`` (5, 3) holds the fan's axis, the line's direction, the apex, ``step_P`` (the part's +x_O motion
    seen from the part) and the receiver: the kernels form a hit face's scalars from it
    (:func:`optipose.scan.kernels.face_terms`), so building a view does not grow with the mesh.
    """

    T_O_S: np.ndarray
    apex_P: np.ndarray  # (3,)
    d_P: np.ndarray  # (n_col, 3) unit ray directions
    o_P32: np.ndarray  # (n_col, 3) ray origins on the window line, float32 for Embree
    d_P32: np.ndarray
    receiver_P: np.ndarray  # (3,)
    step_P: np.ndarray  # (3,)
    fan_lo: np.ndarray  # (3,) the box of the fan's trapezoid (window to far limit) at shift 0
    fan_hi: np.ndarray
    frame: np.ndarray  # (5, 3)

    def rays(
        self, rays: np.ndarray, shift_b: np.ndarray, t_max: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Embree's float32 origins (n, 3), directions (n, 3) and far limits (n,) of a block's rays (profile
        in the block × columns + column) at its shifts (m,): :func:`optipose.scan.kernels.block_rays`."""
        return block_rays(
            np.ascontiguousarray(rays, dtype=np.int64),
            len(self.o_P32),
            shift_b,
            self.o_P32,
            self.d_P32,
            self.step_P,
            t_max,
        )

    @classmethod
    def build(
        cls, sensor, ray_o_S: np.ndarray, ray_d_S: np.ndarray, t_max: np.ndarray, T_O_S: np.ndarray, T_O_P: np.ndarray
    ) -> SensorView:
        """The view of ``sensor`` (a :class:`~optipose.model.sensor.SensorModel`) standing at ``T_O_S`` (4×4),
        the part at ``T_O_P`` (4×4); ``ray_o_S``, ``ray_d_S`` (n_col, 3): its laser rays in its own frame,
        ``t_max`` (n_col,) float32: each ray's far limit."""
        R_PO, t_OP = T_O_P[:3, :3].T, T_O_P[:3, 3]
        R_PS = R_PO @ T_O_S[:3, :3]
        to_P = lambda p_S: R_PO @ (T_O_S[:3, :3] @ p_S + T_O_S[:3, 3] - t_OP)  # noqa: E731
        apex_P = to_P(np.array([0.0, 0.0, sensor.apex_z]))
        receiver_P = to_P(sensor.receiver)
        o_P = ray_o_S @ R_PS.T + (to_P(np.zeros(3)))
        d_P = ray_d_S @ R_PS.T
        step_P = R_PO[:, 0].copy()
        t_far = t_max[[0, -1]]
        corners = np.vstack([o_P[[0, -1]], o_P[[0, -1]] + t_far[:, None] * d_P[[0, -1]]])
        return cls(
            T_O_S=T_O_S,
            apex_P=apex_P,
            d_P=d_P,
            o_P32=o_P.astype(np.float32),
            d_P32=d_P.astype(np.float32),
            receiver_P=receiver_P,
            step_P=step_P,
            fan_lo=corners.min(axis=0) - 1e-6,
            fan_hi=corners.max(axis=0) + 1e-6,
            frame=np.array([R_PS[:, 2], R_PS[:, 0], apex_P, step_P, receiver_P]),
        )
