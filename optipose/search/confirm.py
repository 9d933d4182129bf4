"""Stage: confirmation on the objective's full protocol (selection seed).

A 14-scan median and 75th percentile are noisy enough that a polish tuned on them can win there and lose
on a fresh seed (part C did). So the leading candidates of a k, and the one whose axes exceed the hand
layout's least, re-run the full protocol and the best there is kept; the hand layout's own full-protocol
statistics are the bar. Afterwards a k finalist gives way to the best k sensors of a larger finalist when
those do better there.
"""

from __future__ import annotations

import numpy as np

from optipose.verdict.compare import rank
from optipose.evaluate.evaluator import Evaluator
from optipose.search.candidates import distinct
from optipose.search.driver import apart
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Found, IcpEvaluation
from optipose.model.baseline import baseline

__all__ = ["Confirmer"]


class Confirmer:
    """Full-protocol evaluations of the hand layout and of candidates, each run once."""

    def __init__(self, part, objective, seed: int, jobs: int):
        self.part, self.evaluator = part, Evaluator(part, objective, seed=seed, jobs=jobs, quiet=True)
        self._baseline = None
        self._results: dict[bytes, object] = {}  # layout parameters -> its full-protocol evaluation
        self.chosen: dict[int, tuple] = {}  # k -> rank of the confirmed finalist

    def reference(self, on_stage=None):
        """The hand layout's full-protocol evaluation."""
        if self._baseline is None:
            if on_stage:
                on_stage("confirming on the full protocol: the hand-placed layout")
            self._baseline = self.evaluator(baseline(self.part))
        return self._baseline

    def evaluate(self, layout: Found):
        key = np.asarray(layout.u, dtype=float).tobytes()
        if key not in self._results:
            self._results[key] = self.evaluator(layout.poses)
        return self._results[key]

    def pick(
        self,
        k: int,
        pool: list[tuple[tuple, Found]],
        n: int,
        records: list[IcpEvaluation],
        on_stage=None,
        near: Found | None = None,
    ) -> Found:
        """The best on the full protocol of the n leaders of ``pool`` (by their reduced-protocol rank) and
        ``near``, the one whose axes exceed the hand layout's least there: on 14 scans a layout that truly
        beats the hand one on every axis can miss on one axis and rank below wider but lopsided wins (B's
        one sensor did)."""
        reference = self.reference(on_stage).table[k - 1]
        keys = {id(f): key for key, f in pool}
        leaders = distinct([f for _, f in pool], 0.02, key=lambda f: keys[id(f)])[:n]
        if near is not None and apart(near.u, [f.u for f in leaders], 0.02):
            leaders.append(near)
        best, best_key = None, None
        for cand in leaders:
            if on_stage:
                on_stage(f"confirming k={k} on the full protocol ({cand.strategy})")
            choice = self.evaluate(cand).table[k - 1]
            key = rank(choice, reference)
            records.append(IcpEvaluation(k, f"confirm: {cand.strategy}", cand.score, "full", choice, not key[0]))
            if best_key is None or key < best_key:
                best, best_key = cand, key
        self.chosen[k] = best_key
        return best

    def adopt_subsets(
        self, problem: SurrogateProblem, finalists: dict[int, Found], records: list[IcpEvaluation], on_stage=None
    ) -> None:
        """A confirmed k finalist gives way to the best k sensors of a larger finalist when those do better
        on the full protocol: the per-axis assignment of a triple's evaluation is a pair result as well,
        and the validation evaluates such a nested layout inside the larger one, as here."""
        for k, key in sorted(self.chosen.items()):
            reference = self.reference(on_stage).table[k - 1]
            for big in [finalists[kk] for kk in sorted(finalists) if kk > k]:
                if on_stage:
                    on_stage(f"confirming k={k}: the best {k} of the k={big.k} finalist")
                choice = self.evaluate(big).table[k - 1]
                u = np.concatenate([big.sensor(i) for i in choice.sensors])
                score = problem.score(u)
                new = rank(choice, reference)
                records.append(
                    IcpEvaluation(k, f"best {k} of the k={big.k} finalist", score.objective, "full", choice, not new[0])
                )
                if score.feasible and new < key:
                    finalists[k] = Found(
                        k, f"best {k} of the k={big.k} finalist", u, problem.space.to_poses(u), score.value, score.stats
                    )
                    key = self.chosen[k] = new
