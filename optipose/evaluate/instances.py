"""Layouts checked in cell instances a search never saw: held-out draws of a cell's ranges, the ranges' ends, and
other presets (``optipose robustness``; docs/conditions.md).

A cell with ranges (:mod:`optipose.cell.ranges`) says what is not known about a user's cell; a found layout is
worth its brackets only where it stays better than the hand one across what the ranges allow. :func:`instances`
names the cells to check in: per cell, a few held-out draws of its ranges (one instance per seed, the seeds derived
from the run's by :func:`optipose.seeds.held_out_seed`) and, for a cell with ranges, every range at its low end and
every range at its high end (:meth:`optipose.cell.config.Cell.at`). :func:`check` evaluates every layout in every
instance with one evaluator per instance (the same seed, so the same part as made, calibration, paths and noise for
every layout: a layout against itself is an exact tie), each layout choosing its subsets per axis on that evaluation
as ``optipose evaluate`` does, and gives one :class:`InstanceRow` per (instance, layout, k, axis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.cell.config import Cell, load_cell
from optipose.evaluate.evaluator import Evaluator
from optipose.seeds import held_out_seed

__all__ = ["Instance", "InstanceRow", "instances", "check", "summary", "TIE"]

# hand / layout within this of 1 is a tie, and a tie holds: two evaluations of the same sensors in a sub-layout and in
# the whole one can differ in the last bits of a statistic (the order of a sum), never by more
TIE = 1e-9


@dataclass(frozen=True)
class Instance:
    """One cell instance to check in: ``cell`` (named as given, e.g. ``cobot`` or ``cobot:zeroed``), what the
    instance is (``draw 1``, ``low ends``, ``high ends``), the point cell or the ranged one its ``seed`` draws."""

    cell: str
    label: str
    seed: int
    the_cell: Cell


@dataclass(frozen=True)
class InstanceRow:
    """One figure of a check: a layout's choice of k sensors in one instance, on one axis (rad), and the hand
    layout's choice of as many there; ``ratio`` is hand / layout of the paper's score (the sum over the axes of
    median and 75th percentile) of the whole choice, ``holds`` whether it is at least 1 (within :data:`TIE`)."""

    cell: str
    instance: str
    seed: int
    layout: str
    k: int
    sensors: str
    axis: str
    subset: str
    median: float
    p75: float
    hand_sensors: str
    hand_median: float
    hand_p75: float
    score: float
    hand_score: float

    @property
    def ratio(self) -> float:
        return float(self.hand_score / self.score) if self.score > 0 else float("inf")

    @property
    def holds(self) -> bool:
        return self.ratio >= 1.0 - TIE


def instances(cells: list[str], seed: int, draws: int = 3, ends: bool = True) -> list[Instance]:
    """The instances of each of ``cells`` (shipped names, ``NAME:zeroed`` or files): ``draws`` held-out draws of its
    ranges (a cell of points: ``draws`` instances of its realisations), then, with ranges and ``ends``, its low
    and its high ends (with the first held-out seed's realisations)."""
    out = []
    for name in cells:
        cell = load_cell(name)
        seeds = [held_out_seed(seed, i) for i in range(draws)]
        out += [Instance(name, f"draw {i + 1}", s, cell) for i, s in enumerate(seeds)]
        if ends and cell.ranges:
            out += [Instance(name, f"{end} ends", seeds[0], cell.at(end)) for end in ("low", "high")]
    return out


def check(part, hand, layouts: dict, objective, instances: list[Instance], jobs: int = 1) -> list:
    """Every layout of ``layouts`` (name → Layout) and the ``hand`` layout in each instance: one evaluator per
    instance (``objective`` in the instance's cell, its seed), its orientations spread over ``jobs`` workers
    (:mod:`optipose.parallel.executors`). Per layout, k from 1 to its size (at most the hand layout's), its choice
    of k sensors against the hand layout's: :class:`InstanceRow` s."""
    rows = []
    for inst in instances:
        with Evaluator(part, objective.in_cell(inst.the_cell), seed=inst.seed, jobs=jobs, quiet=True) as evaluator:
            reference = {c.k: c for c in evaluator(hand).table}
            for name, layout in layouts.items():
                table = evaluator(layout).table
                for choice in table[: min(len(table), len(reference))]:
                    rows += _rows(inst, name, choice, reference[choice.k])
    return rows


def _rows(inst: Instance, name: str, choice, reference) -> list[InstanceRow]:
    return [
        InstanceRow(
            inst.cell,
            inst.label,
            inst.seed,
            name,
            choice.k,
            choice.name,
            a.axis,
            a.label,
            float(a.median),
            float(a.p75),
            reference.name,
            float(h.median),
            float(h.p75),
            float(choice.score),
            float(reference.score),
        )
        for a, h in zip(choice.axes, reference.axes)
    ]


def summary(rows: list[InstanceRow]) -> list[tuple[str, int, int, int, float]]:
    """Per (layout, k): in how many instances it holds, of how many, and its smallest ratio."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r.layout, r.k), {})[(r.cell, r.instance)] = r.ratio
    return [
        (name, k, sum(v >= 1 for v in g.values()), len(g), float(np.min(list(g.values()))))
        for (name, k), g in groups.items()
    ]
