"""The surrogate as an emulator of a layout's Table 1 for any magnitudes of a cell (docs/calibration.md).

The surrogate's cell term (:mod:`optipose.search.cell_terms`) keeps each error source group's variance apart
(``GROUPS``); a cell instance's variance is the material's white noise plus Σ_g f_g V_g, with f_g = (magnitude_g /
middle_g)² the group's variance factor. :class:`Emulator` builds the surrogate's maps of a layout's sensors once, at
the cell's middles, takes each subset's V_g from :func:`~optipose.search.cell_terms.subset_terms` on a basis of
factors (all zero, then one group at a time), and then predicts the median and 75th percentile of |error| per subset
and axis for thousands of magnitude settings in seconds: a linear recombination of variances, then the surrogate's
statistics of |δ + σ z| over its turns (:func:`~optipose.search.prediction.instance_stats`).

What it leaves out, besides what the surrogate leaves out: the path's correlation length (the modes are built at its middle: a range of it
is not emulated, :attr:`Emulator.fixed`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from optipose.evaluate.assignment import all_subsets, subset_name
from optipose.search.cell_terms import GROUPS, subset_terms
from optipose.search.prediction import instance_stats
from optipose.search.surrogate import Surrogate, bias_rotation, protocol_turns, rotation_sigma

__all__ = ["Emulator", "SubsetTerms", "field_value"]

_CHUNK = 2048  # magnitude settings per pass (memory: chunk × turns × 16 × 3 floats per subset)


@dataclass(frozen=True)
class SubsetTerms:
    """One subset's emulated error: noise σ² (3,) rad² of the sensors, the bias δ (turns, 3) rad (voxels and the
    material's sub-surface bias), the variance that no magnitude scales (turns, 3) rad² (the material's white noise)
    and each group's variance at unit factor V (groups, turns, 3) rad²."""

    noise: np.ndarray
    bias: np.ndarray
    base: np.ndarray
    groups: np.ndarray


class Emulator:
    """A layout's predicted Table 1 in a cell for any magnitudes of its ranged keys.

    part : a loaded part; layout : its layout (the hand one); objective : the objective, its ``cell`` the prior
    (a cell of ranges). ``keys`` are the ranges' fields it emulates (those in ``GROUPS``, sorted), ``fixed`` the
    ranges' fields it keeps at their middle.
    """

    def __init__(self, part, layout, objective):
        from optipose.cell.scans import CellSetup

        cell = objective.cell
        if cell.ideal:
            raise ValueError("the ideal cell has no magnitude to emulate")
        surrogate = Surrogate(
            part,
            voxel=objective.registration.voxel_size,
            turns=protocol_turns(objective),
            cell=CellSetup.of(cell, part),
        )
        infos = [surrogate.info(T) for T in layout.poses]
        self.infos = infos  # the surrogate's, per sensor (its cell maps at the middles)
        self.names = list(layout.names)
        self.ranges = tuple(cell.ranges)
        self.keys = tuple(f for f, _, _ in self.ranges if f in GROUPS)
        self.fixed = tuple(f for f, _, _ in self.ranges if f not in GROUPS)
        mid = cell.middle()
        self.middles = {g: field_value(mid, g) for g in GROUPS}
        self.subsets = [s for s in all_subsets(len(infos)) if all(infos[i].n_voxels for i in s)]
        self.terms = {subset_name(s, self.names): _terms([infos[i] for i in s]) for s in self.subsets}

    @property
    def labels(self) -> list[str]:
        """The emulated subsets' names (``S1``, ``S1S2``, ...)."""
        return list(self.terms)

    def factors(self, values: np.ndarray) -> np.ndarray:
        """(n, groups) variance factors of magnitude settings ``values`` (n, len(keys)) SI, in :attr:`keys`' order;
        a group that is not a key keeps factor 1 (its middle)."""
        values = np.atleast_2d(np.asarray(values, float))
        f = np.ones((len(values), len(GROUPS)))
        for j, key in enumerate(self.keys):
            g = GROUPS.index(key)
            f[:, g] = (values[:, j] / self.middles[key]) ** 2 if self.middles[key] > 0 else 0.0
        return f

    def stats(self, values: np.ndarray, subsets: list[str] | None = None) -> dict[str, np.ndarray]:
        """Per subset name, (n, 2, 3) rad: the predicted median and 75th percentile of |error| per axis (roll, pitch,
        yaw) at each of the magnitude settings ``values`` (n, len(keys)) SI."""
        f = self.factors(values)
        out = {}
        for name in subsets or self.labels:
            t = self.terms[name]
            chunks = []
            for lo in range(0, len(f), _CHUNK):
                var = t.noise + t.base[None] + np.einsum("kg,gti->kti", f[lo : lo + _CHUNK], t.groups)
                chunks.append(np.stack(instance_stats(np.sqrt(np.clip(var, 0.0, None)), t.bias), axis=1))
            out[name] = np.concatenate(chunks)
        return out


def field_value(cell, name: str) -> float:
    """A cell's magnitude by its field name (``robot.path``, ``calibration.frame_rotation``, ``process_scale``)."""
    if "." not in name:
        return float(getattr(cell, name))
    table, key = name.split(".")
    return float(getattr(getattr(cell, table), key))


def _terms(infos: list) -> SubsetTerms:
    """A subset's :class:`SubsetTerms` from its sensors' surrogate information."""
    H = sum(i.H for i in infos)
    A = sum(i.A for i in infos)
    delta = bias_rotation(A, sum(i.G for i in infos))
    basis = np.vstack([np.zeros(len(GROUPS)), np.eye(len(GROUPS))])  # all off, then each group at factor 1
    maps = [replace(i.cell, magnitudes=basis) for i in infos]
    var, cell_bias = subset_terms(maps)  # (groups + 1, turns, 3)
    return SubsetTerms(rotation_sigma(H) ** 2, delta + cell_bias, var[0], var[1:] - var[:1])
