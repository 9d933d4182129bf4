"""What an evaluator has registered already, looked up for the next layout that has the same sensors in the same
places.

A sensor's scan at an orientation is a function of the evaluator's seed, the scan, the sensor's model and pose and its
place in the layout (its index and its place in its model's group: its noise key, its bracket's calibration draw and
the material's key follow them, :mod:`optipose.evaluate.worker`, :mod:`optipose.cell.scans`), never of the layout's
other sensors. So is a subset's registration on the part's reference, started from identity. The selection's
hand-anchored layouts keep hand sensors in their places, and a (k−1) finalist plus one keeps the finalist's: their
subsets' rows are taken from the first evaluation that registered them, to the bit, instead of being registered
again, and a subset with another sensor registers the known sensors' down-sampled clouds instead of scanning them
again. (A verdict's draw evaluates its layouts together in one map, an evaluator of its own: it takes nothing.)
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from optipose.evaluate.assignment import all_subsets, subset_name
from optipose.evaluate.worker import WorkerSetup, sensor_groups
from optipose.model.layout import Layout

__all__ = ["Registered", "sensor_keys"]

_NO_TIME = {"scan": 0.0, "register": 0.0}
CLOUD_BYTES = 256 * 2**20  # the clouds one evaluator keeps: all of a selection's on a part like B


def sensor_keys(layout: Layout, default) -> list[tuple]:
    """Per sensor of ``layout``, what its scans depend on besides the scan: its index, its model's group and its
    place there (:func:`~optipose.evaluate.worker.sensor_groups`; ``default`` the part's model), the model and
    the pose's bytes."""
    models = [s.sensor for s in layout.sensors]
    keys: list = [None] * len(models)
    for g, (model, indices) in enumerate(sensor_groups(models, default)):
        for place, j in enumerate(indices):
            keys[j] = (j, g, place, str(model), np.asarray(layout.poses[j], dtype=float).tobytes())
    return keys


class Registered:
    """One evaluator's registered rows, per (scan, subset's sensor keys), its sensors' point counts, per (scan,
    sensor key), and the down-sampled clouds of its sensors' scans, the most recent first, up to ``CLOUD_BYTES``.
    Off (every subset registered again) where a subset's rows would depend on more than its own sensors' scans: a
    subset started where its sensors' own registrations put it (``subset_start = "combined"``), whose rows are its
    singles' too."""

    def __init__(self, setup: WorkerSetup):
        self.default = setup.sensor
        self.on = setup.registration.subset_start != "combined"
        self._rows: dict = {}
        self._points: dict = {}
        self._clouds: OrderedDict = OrderedDict()
        self._bytes = 0

    def plan(self, layout: Layout, subsets: list[tuple] | None, scans: list[int]) -> tuple:
        """(subsets to register, or ``None`` for every one; the known rows as one worker output, or ``None``;
        whether the workers have anything to do; per scan index, the known clouds by sensor index) for ``layout``
        at the scans ``scans`` (indices), ``subsets`` the wanted ones (``None``: every one)."""
        if not self.on or not self._rows:
            return subsets, None, True, {}
        every = all_subsets(len(layout))
        wanted = every if subsets is None else subsets
        keys = sensor_keys(layout, self.default)
        known = [s for s in wanted if all((i, tuple(keys[j] for j in s)) in self._rows for i in scans)]
        given = {}
        for i in scans:
            mine = {j: self._clouds[(i, key)] for j, key in enumerate(keys) if (i, key) in self._clouds}
            if mine:
                given[i] = mine
                for j in mine:
                    self._clouds.move_to_end((i, keys[j]))
        if not known:
            return subsets, None, True, given
        names = list(layout.names)
        rows = [
            self._rows[(i, tuple(keys[j] for j in s))]
            | {"subset_index": every.index(s), "subset": subset_name(s, names)}
            for i in scans
            for s in known
        ]
        todo = [s for s in wanted if s not in known]
        counted = all((i, key) in self._points for i in scans for key in keys)
        points = []
        if not todo and counted:  # nothing to scan: the point counts come from here too
            points = [
                self._points[(i, key)] | {"sensor_index": j, "sensor": names[j]}
                for i in scans
                for j, key in enumerate(keys)
            ]
        return todo, (rows, points, dict(_NO_TIME), {}), bool(todo) or not counted, given

    def add(self, layout: Layout, outputs: list[tuple]) -> None:
        """Keep the rows and point counts of the workers' ``outputs`` of ``layout``."""
        if not self.on:
            return
        every = all_subsets(len(layout))
        keys = sensor_keys(layout, self.default)
        for rows, points, _, clouds in outputs:
            for row in rows:
                subset = every[row["subset_index"]]
                self._rows[(row["scan"], tuple(keys[j] for j in subset))] = row
            for row in points:
                self._points[(row["scan"], keys[row["sensor_index"]])] = row
            for (i, j), known in clouds.items():
                if (i, keys[j]) not in self._clouds:
                    self._clouds[(i, keys[j])] = known
                    self._bytes += known[0].nbytes
        while self._bytes > CLOUD_BYTES:
            _, (cloud, _) = self._clouds.popitem(last=False)
            self._bytes -= cloud.nbytes
