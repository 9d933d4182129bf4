"""Scans out and scans in: a protocol written as a cell's sensors report it, and a scan folder evaluated as
a simulation is (docs/scans.md).

:func:`record_protocol` scans a layout at every orientation of an objective's protocol through the
evaluation's own worker (:meth:`Evaluator.record`: the cell's sources, the noise, each point what its
reported height gives) and writes a scan folder (:mod:`optipose.scan.folder`). :func:`evaluate_scans` reads
one — simulated or measured — and registers it with the objective's pipeline (:meth:`Evaluator.replay`):
on a folder :func:`record_protocol` wrote in ``.npy``, the simulation's result bit for bit.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from optipose.cell.config import IDEAL
from optipose.errors import ConfigError
from optipose.evaluate.evaluator import EvaluationResult, Evaluator
from optipose.evaluate.objective import Objective, load_objective, objective_from_dict
from optipose.model.layout import Layout, SensorPose
from optipose.scan.folder import (
    FORMATS,
    Manifest,
    ProfileReader,
    ProfileWriter,
    ScanEntry,
    part_fingerprint,
    read_manifest,
    write_manifest,
)

__all__ = ["record_protocol", "evaluate_scans", "scan_objective"]

log = logging.getLogger(__name__)

_ANGLE_TOLERANCE_DEG = 1e-6  # a manifest's set orientation is the protocol's within this
_OFFSET_TOLERANCE_MM = 1e-6


def record_protocol(
    part, layout: Layout, objective: Objective, folder: Path, seed: int = 0, jobs: int = 1, format: str = "npy"
) -> Manifest:
    """Write the scan folder of ``layout`` on ``part`` under ``objective``'s protocol and cell, run seed
    ``seed``: one profile file per scan and sensor, and the manifest (written last)."""
    if format not in FORMATS:
        raise ConfigError(f"--format {format}: use one of {', '.join(FORMATS)}")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    layout = _with_models(layout, part)
    with Evaluator(part, objective, seed=seed, jobs=jobs) as evaluator:
        p = evaluator.perturbations
        writer = ProfileWriter(folder, tuple(str(label) for label in p.label), tuple(layout.names), format)
        files = evaluator.record(layout, writer)
        motion = evaluator.setup.motion
    scans = tuple(
        ScanEntry(str(p.label[i]), _listed(np.rad2deg(p.rpy[i])), _listed(p.offset[i] * 1e3), tuple(files[i]))
        for i in range(len(p))
    )
    manifest = Manifest(
        part=part.name,
        fingerprint=part_fingerprint(part.mesh.vertices),
        layout=layout,
        step=motion.step,
        profiles=motion.n_profiles,
        objective=objective.name,
        cell=objective.cell.name,
        seed=int(seed),
        scans=scans,
        settings=objective.to_dict(),
    )
    write_manifest(folder, manifest)
    return manifest


def scan_objective(manifest: Manifest, objective: str | Objective | None = None) -> Objective:
    """The objective a scan folder is evaluated under: ``objective`` if given, else the manifest's, in the
    manifest's cell (what the result says it is); refused when the evaluation needs more than the scans."""
    if objective is None and manifest.settings:  # the objective the folder was written under, as it was
        return _checked(objective_from_dict(manifest.settings), manifest)
    chosen = objective if isinstance(objective, Objective) else load_objective(objective or manifest.objective)
    try:
        chosen = chosen.in_cell(manifest.cell)
    except ConfigError:  # a real cell, or a cell file not here: the scans carry its sources, none is added
        log.info("cell '%s' of the scans is not a cell file here: its sources are in the scans", manifest.cell)
        chosen = replace(chosen, cell=replace(IDEAL, name=manifest.cell, description="the scans' own cell"))
    return _checked(chosen, manifest)


def _checked(chosen: Objective, manifest: Manifest) -> Objective:
    """``chosen``, refused when evaluating the scans under it needs more than the scans."""
    if chosen.cell.calibration.zeroed:
        raise ConfigError(
            f"scans of cell '{manifest.cell}', zeroed on a master part: the zero needs the master's scans, "
            "which a scan folder does not hold"
        )
    if chosen.registration.reference == "nominal-scan":
        raise ConfigError(
            f"objective '{chosen.name}' registers on a nominal scan, which a scan folder does not hold; "
            "use reference = cad-surface or cad-sample"
        )
    return chosen


def evaluate_scans(
    part, folder: Path, objective: str | Objective | None = None, jobs: int = 1
) -> tuple[EvaluationResult, Manifest]:
    """Evaluate the scan folder ``folder`` of ``part`` under ``objective`` (default: the manifest's): the
    result of a simulated evaluation with the manifest's layout, cell and seed, from the scans read."""
    folder = Path(folder)
    manifest = read_manifest(folder)
    fingerprint = part_fingerprint(part.mesh.vertices)
    if manifest.fingerprint != fingerprint:
        raise ConfigError(
            f"--scans {folder}: scans of part '{manifest.part}' ({manifest.fingerprint}), not of "
            f"'{part.name}' ({fingerprint}): another mesh"
        )
    the_objective = scan_objective(manifest, objective)
    with Evaluator(part, the_objective, seed=manifest.seed, jobs=jobs) as evaluator:
        files, rpy = _matched(manifest, evaluator, folder)
        reader = ProfileReader(
            folder, manifest.layout, _models(manifest.layout, part), files, _shifts(manifest, evaluator), rpy
        )
        reader.check()
        return evaluator.replay(manifest.layout, reader), manifest


def _matched(manifest: Manifest, evaluator: Evaluator, folder: Path) -> tuple[dict, dict]:
    """Each scan of the protocol's files and set orientation (rad, the protocol's own numbers), found in
    the manifest by its label, set orientation and offset (the k-th of a kind the k-th); a scan the protocol
    has and the folder lacks is an error."""
    p = evaluator.perturbations
    have = np.array([e.rpy_deg for e in manifest.scans]), np.array([e.offset_mm for e in manifest.scans])
    labels = np.array([e.label for e in manifest.scans])
    files, rpy, used = {}, {}, set()
    for i in range(len(p)):
        close = (
            (labels == str(p.label[i]))
            & (np.abs(have[0] - np.rad2deg(p.rpy[i])).max(axis=1) <= _ANGLE_TOLERANCE_DEG)
            & (np.abs(have[1] - p.offset[i] * 1e3).max(axis=1) <= _OFFSET_TOLERANCE_MM)
        )
        close[list(used)] = False  # the nominal orientation is in every sequence: each its own scan
        if not close.any():
            angles = ", ".join(f"{a:.3f}" for a in np.rad2deg(p.rpy[i]))
            raise ConfigError(
                f"--scans {folder}: scan {i} ({p.label[i]}) of objective '{evaluator.objective.name}''s protocol, "
                f"roll, pitch, yaw = {angles} deg, is not in the manifest"
            )
        k = int(np.flatnonzero(close)[0])
        used.add(k)
        files[i], rpy[i] = manifest.scans[k].files, p.rpy[i]
    if len(used) < len(manifest.scans):
        log.warning("%d scans of %s are not in the protocol and are left out", len(manifest.scans) - len(used), folder)
    return files, rpy


def _shifts(manifest: Manifest, evaluator: Evaluator) -> np.ndarray:
    """The motion's offsets (m): the evaluation's own when the manifest's travel is the part's (the same
    numbers), else the manifest's."""
    motion = evaluator.setup.motion
    if manifest.profiles == motion.n_profiles and abs(manifest.step - motion.step) <= 1e-12:
        return motion.offsets()
    log.warning(
        "the scans' travel (%d profiles of %.4g mm) is not the part's (%d of %.4g mm); the scans' is used",
        manifest.profiles,
        manifest.step * 1e3,
        motion.n_profiles,
        motion.step * 1e3,
    )
    return manifest.motion().offsets()


def _with_models(layout: Layout, part) -> Layout:
    """``layout`` with each sensor naming its model (the part's where it names none)."""
    return Layout(
        tuple(SensorPose(s.name, s.T_O_S, s.sensor or part.sensor) for s in layout.sensors),
        name=layout.name,
        description=layout.description,
    )


def _models(layout: Layout, part) -> tuple:
    """Each sensor's model as the reader loads it: a name or a path."""
    return tuple(s.sensor or part.sensor for s in layout.sensors)


def _listed(values) -> tuple[float, float, float]:
    return tuple(float(v) for v in values)
