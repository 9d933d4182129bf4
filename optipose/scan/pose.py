"""Where the part stands for one scan: the record every scan of :class:`optipose.scan.scanner.Scanner` takes."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.transforms import part_motion

__all__ = ["PartPose", "NOMINAL"]


@dataclass(frozen=True)
class PartPose:
    """The part's pose for a scan: turned by ``rpy`` about ``centre``, then moved by ``offset``.

    rpy : (3,) rad, the part's roll, pitch and yaw (a protocol's orientation).
    centre : (3,) m, the rotation centre in O (a part's ``rotation_centre``).
    offset : (3,) m, an extra translation of the part (protocols with translation offsets), or None.
    """

    rpy: np.ndarray | tuple = (0.0, 0.0, 0.0)
    centre: np.ndarray | tuple = (0.0, 0.0, 0.0)
    offset: np.ndarray | None = None

    @property
    def T_O_P(self) -> np.ndarray:
        """The part's pose (4, 4): :func:`optipose.transforms.part_motion` of the rotation and the offset."""
        return part_motion(np.asarray(self.rpy, float), np.asarray(self.centre, float), self.offset)


NOMINAL = PartPose()  # the part unturned about O's origin: a scan's default
