"""The scan's motion: the part carried along ``+x_O`` in equal steps while the sensors stay still (docs/method.md, "The scan and the protocol")."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ScanMotion"]


@dataclass(frozen=True)
class ScanMotion:
    """The part's travel along ``+x_O``: ``length`` (m) in ``step`` (m) increments, centred on the nominal pose.

    Profile k is taken with the part shifted by ``offsets()[k]``; the sensor poses are given at shift 0,
    so a sensor aimed at the middle of the part sweeps the whole scanning length.
    """

    length: float
    step: float = 0.5e-3

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.step > 0):
            raise ValueError("scan length and step must be positive")

    @property
    def n_profiles(self) -> int:
        return max(1, int(round(self.length / self.step)))

    def offsets(self) -> np.ndarray:
        """Part shifts along +x_O (n_profiles,), m."""
        n = self.n_profiles
        return (np.arange(n) + 0.5) * self.step - 0.5 * n * self.step
