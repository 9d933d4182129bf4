"""Layouts as a robot program wants them: each sensor's 4×4 ``T_O_S`` and its XYZ (mm) + RPY (deg), with
a copy button (docs/conventions.md: RPY extrinsic about x_O, y_O, z_O, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``)."""

from __future__ import annotations

import numpy as np

from optipose.report.document import Block, Code, Heading, Paragraph, Table
from optipose.transforms import xyz_rpy

__all__ = ["layout_section", "pose_text"]


def pose_text(name: str, T_O_S: np.ndarray) -> str:
    """A sensor's pose as text to paste: the 4×4 (m) and the XYZ (mm) + RPY (deg) line."""
    xyz, rpy = xyz_rpy(T_O_S)
    rows = "\n".join("[" + ", ".join(f"{v: .6f}" for v in row) + "]" for row in np.asarray(T_O_S, float))
    return (
        f"# {name}: T_O_S (m)\n{rows}\n"
        f"# {name}: X Y Z (mm), roll pitch yaw (deg, extrinsic xyz)\n"
        + ", ".join(f"{v:.3f}" for v in xyz)
        + ", "
        + ", ".join(f"{v:.4f}" for v in rpy)
    )


def layout_section(title: str, layout, note: str = "") -> list[Block]:
    """A heading, a table of XYZ + RPY per sensor and one copyable block per sensor."""
    rows = []
    for s in layout.sensors:
        xyz, rpy = xyz_rpy(s.T_O_S)
        rows.append((s.name, *(f"{v:.3f}" for v in xyz), *(f"{v:.4f}" for v in rpy), s.sensor or "part's"))
    blocks: list[Block] = [Heading(title, 3)]
    if note:
        blocks.append(Paragraph(note, "note"))
    blocks.append(
        Table(
            ("sensor", "X (mm)", "Y (mm)", "Z (mm)", "roll (deg)", "pitch (deg)", "yaw (deg)", "model"),
            tuple(rows),
            caption=f"{title}: R (the middle of the measuring range) in O, and the sensor frame's "
            "orientation as extrinsic roll, pitch, yaw about x_O, y_O, z_O",
        )
    )
    blocks += [Code(pose_text(s.name, s.T_O_S), f"{s.name}") for s in layout.sensors]
    return blocks
