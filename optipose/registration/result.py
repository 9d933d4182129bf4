"""The records registration answers with: :class:`Registration` (one result) and :class:`Matches` (closest
reference points of a cloud, reusable across the subsets that contain it).

The information matrix is the point-to-plane ``H = Σ Jᵢᵀ Jᵢ``, ``Jᵢ = [((pᵢ − c) × nᵢ)ᵀ, nᵢᵀ]`` about the
cloud's centroid c (rotation first, rad, then translation, m), for observability
(:func:`optipose.registration.preprocess.information_matrix`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Registration", "Matches", "MIN_POINTS"]

MIN_POINTS = 6  # fewest points (and inliers) a registration is attempted with


@dataclass
class Matches:
    """Closest reference points ``q`` (n, 3) m, their unit normals ``n`` (n, 3) and ids ``ids`` (n,) int64
    for a cloud of n points at identity; ``margin`` (n,) m, when the reference gives it: how far each point
    can move before another reference point may be closer (:class:`~optipose.registration.sampled.SampleTracker`)."""

    q: np.ndarray
    n: np.ndarray
    ids: np.ndarray
    margin: np.ndarray | None = None

    @staticmethod
    def concat(parts: list["Matches"]) -> "Matches":
        """The matches of the stacked clouds, in the order given."""
        q, n, ids = (np.concatenate([getattr(m, k) for m in parts]) for k in ("q", "n", "ids"))
        margin = np.concatenate([m.margin for m in parts]) if all(m.margin is not None for m in parts) else None
        return Matches(q, n, ids, margin)


@dataclass
class Registration:
    """Result of one registration of a scan (source) onto a reference (target).

    T_target_source : (4, 4) rigid transform, m; maps scan points onto the reference (the reference frame
        O from the scan's frame O', i.e. the inverse of the part's applied motion).
    converged : the step fell below the tolerances before ``max_iterations``.
    iterations : ICP steps taken (-1 when the back-end does not say).
    fitness : fraction of the points within the max correspondence distance, in [0, 1].
    rmse : m, RMS distance over those inliers (NaN for a failed registration).
    n_points : points in the source.
    information : (6, 6) symmetric positive semi-definite, see the module doc.
    failure : why the registration is not usable ("" when it is).
    matched : (n,) int64, the reference id each source point was matched to at the last step (back-ends
        that track matches; ``None`` otherwise). Other subsets of the same clouds start from them.
    """

    T_target_source: np.ndarray = field(repr=False)
    converged: bool
    iterations: int
    fitness: float
    rmse: float
    n_points: int
    information: np.ndarray = field(repr=False)
    failure: str = ""
    matched: np.ndarray | None = field(default=None, repr=False)

    @property
    def ok(self) -> bool:
        return self.converged and not self.failure

    @classmethod
    def failed(cls, n_points: int, why: str, T: np.ndarray | None = None, iterations: int = 0) -> "Registration":
        """A failed registration of ``n_points`` points: ``why`` it failed, the pose reached (default identity)."""
        return cls(np.eye(4) if T is None else T, False, iterations, 0.0, float("nan"), n_points, np.zeros((6, 6)), why)
