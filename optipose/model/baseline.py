"""The baseline a search and a report compare against: the part's hand-placed layout, or for a part
without one (a bare STL) the **conventional placement** the shipped parts use.

The conventional placement (docs/parts.md, the paper's Part B): three sensors in one plane across the motion
(their laser lines across ``+x_O``, ``y_S = ±x_O``), R mid-length along x —

* S1 looking down at 45° from ``-y`` at the part's left long top edge ``(x_c, y_min, z_max)``,
* S2 looking straight down at the top ``(x_c, y_c, z_max)``,
* S3 looking down at 45° from ``+y`` at the right long top edge ``(x_c, y_max, z_max)``.

Heads clear of the part: each head is backed off along its viewing axis (the aim point stays inside the
measuring range) until :mod:`optipose.model.collision` finds it at least the clearance margin from the
part swept along the scan and from the keep-outs, and the three heads clear of each other; when S2's
head would touch a diagonal one, S2 is turned half a turn about ``z_S`` (its head on the ``-x`` side of its
laser plane) and moved 2.5 mm along ``-x``, as parts A and C place it.
"""

from __future__ import annotations

import itertools

import numpy as np

from optipose.model.layout import Layout, SensorPose

__all__ = ["CONVENTIONAL", "conventional_layout", "baseline", "baseline_label"]

CONVENTIONAL = "conventional"
_DESCRIPTION = (
    "conventional placement: S1 and S3 look down at 45 deg at the two long top edges from -y and +y, "
    "S2 straight down at the top; laser lines across the motion, R mid-length, heads backed off along "
    "their viewing axes until clear of the part"
)
_STEP = 1e-3  # m, standoff increments
_S2_SHIFT = 2.5e-3  # m along -x when S2 is turned (parts A and C)
_C = np.sqrt(0.5)


def baseline(part) -> Layout | None:
    """The layout a found one is compared against: ``hand`` when the part has it, else ``conventional``."""
    return part.layouts.get("hand") or part.layouts.get(CONVENTIONAL)


def baseline_label(layout) -> str:
    """``hand`` or ``conventional``: what a report and the terminal call the baseline."""
    if layout is None:
        return "hand"
    is_conventional = layout.name == CONVENTIONAL or layout.description.startswith("conventional placement")
    return CONVENTIONAL if is_conventional else "hand"


def _axes() -> dict[str, np.ndarray]:
    """Rotation (3×3, columns x_S, y_S, z_S) per sensor, S2 in its two turns."""
    x = np.array([1.0, 0.0, 0.0])
    return {
        "S1": np.column_stack([[0, _C, _C], x, [0, _C, -_C]]),
        "S2": np.column_stack([[0, 1, 0], x, [0, 0, -1]]),
        "S2 turned": np.column_stack([[0, -1, 0], -x, [0, 0, -1]]),
        "S3": np.column_stack([[0, _C, -_C], x, [0, -_C, -_C]]),
    }


def _pose(R: np.ndarray, aim: np.ndarray, standoff: float) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = aim - standoff * R[:, 2]  # backed off along -z_S: the aim point sits at z_S = +standoff
    return T


def conventional_layout(part, margin: float | None = None) -> Layout:
    """The conventional three-sensor placement for ``part`` (see the module doc), heads clear of the swept
    part, the keep-outs (``margin``, default the collision module's) and each other.

    Raises :class:`~optipose.errors.ConfigError` when no standoff within the measuring range clears them.
    """
    from optipose.errors import ConfigError
    from optipose.model.collision import DEFAULT_MARGIN, collision_model, heads_clearance

    margin = DEFAULT_MARGIN if margin is None else margin
    model = collision_model(part)
    sensor = model.sensor
    lo, hi = np.asarray(part.mesh.bounds, dtype=float)
    xc = 0.5 * (lo[0] + hi[0])
    aims = {
        "S1": np.array([xc, lo[1], hi[2]]),
        "S2": np.array([xc, 0.5 * (lo[1] + hi[1]), hi[2]]),
        "S3": np.array([xc, hi[1], hi[2]]),
    }
    axes = _axes()
    standoffs = np.arange(0.0, 0.8 * 0.5 * (sensor.z_far - sensor.z_near) + 1e-9, _STEP)

    def first_clear(R: np.ndarray, aim: np.ndarray) -> list[np.ndarray]:
        return [T for d in standoffs if not model.collides(T := _pose(R, aim, d), margin)]

    side = {name: first_clear(axes[name], aims[name]) for name in ("S1", "S3")}
    turned_aim = aims["S2"] - np.array([_S2_SHIFT, 0.0, 0.0])
    tops = [(T, False) for T in first_clear(axes["S2"], aims["S2"])] + [
        (T, True) for T in first_clear(axes["S2 turned"], turned_aim)
    ]
    tops.sort(
        key=lambda item: (round(float(item[0][2, 3]), 6), item[1])
    )  # the lowest standoff first, unturned on a tie
    for T1, T3 in itertools.product(side["S1"][:6], side["S3"][:6]):
        if heads_clearance(sensor, T1, sensor, T3) < 0:
            continue
        for T2, _ in tops:
            if heads_clearance(sensor, T1, sensor, T2) >= 0 and heads_clearance(sensor, T3, sensor, T2) >= 0:
                poses = (SensorPose("S1", T1), SensorPose("S2", T2), SensorPose("S3", T3))
                return Layout(poses, name=CONVENTIONAL, description=_DESCRIPTION)
    raise ConfigError(
        f"part '{part.name}': no conventional placement clears the part and its keep-outs within the "
        f"sensor's measuring range; give a layout"
    )
