"""Every seed derived from a run's seed, in one place.

A run has one user-given seed. The stages that need their own noise draw get a seed derived from it
through ``numpy.random.SeedSequence`` with a fixed tag, so each is reproducible, none equals another, and
none equals the run's seed itself: the search scores layouts on the selection seed and reports them on
the validation seed, which it never saw.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "derived_seed",
    "selection_seed",
    "validation_seed",
    "nominal_reference_seed",
    "group_seed",
    "zeroing_seed",
    "verdict_seed",
    "held_out_seed",
    "kind_seed",
]

_SELECTION = 0x5E1EC7
_VALIDATION = 0x7A11D
_NOMINAL_REFERENCE = 7
_SENSOR_MODEL = 0x5E4500  # plus the group's index
_MOUNTING = 0xB4AC7E7
_VERDICT = 0x7E4D1C7
_HELD_OUT = 0x4E1D0  # plus the instance's index: the robustness check's cell instances
_KIND = 0x6B1D0  # plus the kind's index: a BUY raced again in the common kinds of cell


def derived_seed(seed: int, tag: int) -> int:
    """A seed for one purpose (``tag``) of a run with seed ``seed``: a 32-bit int, the same on every machine."""
    return int(np.random.SeedSequence([int(seed), int(tag)]).generate_state(1)[0])


def selection_seed(seed: int) -> int:
    """The noise seed of the search's ICP selection, polish and confirmation: neither the search's nor the
    validation's."""
    return derived_seed(seed, _SELECTION)


def validation_seed(seed: int) -> int:
    """The held-out noise seed of the search's validation: derived from, and never equal to, the search seed."""
    return derived_seed(seed, _VALIDATION)


def verdict_seed(seed: int, draw: int) -> int:
    """The seed of the verdict's draw ``draw`` (a cell instance and its scans' noise, the same for the found
    and the hand layout): draw 0 is the validation's held-out seed, each later one a seed of its own that
    neither the search nor the validation saw."""
    if draw == 0:
        return validation_seed(seed)
    return int(np.random.SeedSequence([int(seed), _VERDICT, int(draw)]).generate_state(1)[0])


def nominal_reference_seed(seed: int) -> int:
    """The noise seed of the nominal-orientation scan that serves as the reference (``reference =
    "nominal-scan"``): a scan of its own, not one of the protocol's."""
    return derived_seed(seed, _NOMINAL_REFERENCE)


def group_seed(seed: int, group: int) -> int:
    """The noise seed of sensor-model group ``group`` of a scan with seed ``seed``: group 0 (the part's
    model) keeps ``seed``; each other model (1, 2, … in the layout's order) gets a derived one, so sensors
    of different models never share a noise draw."""
    return int(seed) if group == 0 else derived_seed(seed, _SENSOR_MODEL + group)


def zeroing_seed(seed: int) -> int:
    """The noise seed of the master-part scan that zeroes a cell."""
    return int(np.random.SeedSequence([int(seed), _MOUNTING, 0, -1 % 2**32]).generate_state(1)[0])


def held_out_seed(seed: int, i: int) -> int:
    """The seed of held-out cell instance ``i`` of ``optipose robustness`` run with ``seed``: none of a search's
    own seeds (its selection, validation and verdict draws derive from other tags)."""
    return derived_seed(seed, _HELD_OUT + int(i))


def kind_seed(seed: int, i: int) -> int:
    """The seed of the race of a search's BUYs in common kind of cell ``i`` (a user who named no cell,
    :mod:`optipose.search.kinds`): its draws are none of the search's own (their verdict seeds derive from it)."""
    return derived_seed(seed, _KIND + int(i))
