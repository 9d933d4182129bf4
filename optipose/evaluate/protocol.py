"""The perturbation protocol: the orientations (and offsets) a part is scanned at (paper Algorithm 3).

The paper's: sequences R, P, Y, RP, PY, YR, RPY; in each the named angles run together from −2° to +2°
in 0.4° steps (11 values), 77 scans. Each scan gets its own noise seed from the run's seed through
``numpy.random.SeedSequence``, so a scan's cloud depends on the seed and its index only, never on how
the work is split over processes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.evaluate.objective import SEQUENCE_AXES, ProtocolConfig

__all__ = ["Perturbations", "perturbations"]


@dataclass(frozen=True)
class Perturbations:
    """The scans of a protocol, in order.

    rpy : (n, 3) float, radians (roll, pitch, yaw about x_O, y_O, z_O, extrinsic).
    offset : (n, 3) float, metres, extra translation of the part.
    label : (n,) str, e.g. "RP" (the sequence, or "random").
    seeds : (n,) uint64, one noise seed per scan.
    """

    rpy: np.ndarray
    offset: np.ndarray
    label: np.ndarray
    seeds: np.ndarray

    def __len__(self) -> int:
        return len(self.rpy)

    def sample(self, n: int, seed: int) -> "Perturbations":
        """``n`` of the scans (all when ``n`` is 0 or not below their number), drawn without replacement by
        ``seed``, in protocol order: a protocol's orientations in proportion, fewer scans."""
        if n <= 0 or n >= len(self):
            return self
        keep = np.sort(np.random.default_rng([int(seed), len(self), int(n)]).choice(len(self), int(n), replace=False))
        return Perturbations(self.rpy[keep], self.offset[keep], self.label[keep], self.seeds[keep])

    def __repr__(self) -> str:
        labels = list(dict.fromkeys(self.label.tolist()))
        span = np.rad2deg(np.abs(self.rpy).max()) if len(self) else 0.0
        return f"Perturbations({len(self)} scans, sequences={labels}, max |angle| = {span:.3g} deg)"


def perturbations(protocol: ProtocolConfig, seed: int = 0) -> Perturbations:
    """The orientations, offsets and per-scan noise seeds of a protocol; same seed, same list."""
    root = np.random.SeedSequence(int(seed))
    draw_ss, noise_ss = root.spawn(2)
    if protocol.kind == "random":
        rpy, label, offset = _random(protocol, np.random.default_rng(draw_ss))
    else:
        rpy, label = _sequences(protocol)
        offset = np.zeros_like(rpy)
    if protocol.offsets:
        k = len(protocol.offsets)
        extra = np.asarray(protocol.offsets, dtype=float)
        rpy, label = np.repeat(rpy, k, axis=0), np.repeat(label, k)
        offset = np.repeat(offset, k, axis=0) + np.tile(extra, (len(offset), 1))
    seeds = np.array([s.generate_state(1, np.uint64)[0] for s in noise_ss.spawn(len(rpy))], dtype=np.uint64)
    return Perturbations(rpy, offset, label, seeds)


def _sequences(protocol: ProtocolConfig) -> tuple[np.ndarray, np.ndarray]:
    n = int(np.floor((protocol.stop - protocol.start) / protocol.step + 1e-9)) + 1
    values = protocol.start + protocol.step * np.arange(n)  # exact multiples: 0 stays 0, no drift
    rows, labels = [], []
    for name in protocol.sequences:
        block = np.zeros((n, 3))
        block[:, list(SEQUENCE_AXES[name])] = values[:, None]
        rows.append(block)
        labels += [name] * n
    return np.concatenate(rows), np.array(labels)


def _random(protocol: ProtocolConfig, rng: np.random.Generator):
    n = protocol.count
    rpy = rng.uniform(-1, 1, (n, 3)) * np.asarray(protocol.range_rpy)
    offset = rng.uniform(-1, 1, (n, 3)) * np.asarray(protocol.range_offset)
    return rpy, np.array(["random"] * n), offset
