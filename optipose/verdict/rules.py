"""The verdict's rules: how a verdict with confidence is reached (:class:`Rules`) and how a search races it
(:class:`VerdictConfig`, the ``verdict`` section of :class:`optipose.search.config.SearchConfig`).

:mod:`optipose.verdict.confidence` decides on paired draws by :class:`Rules`; :mod:`optipose.verdict.racing`
adds draws until that decision is clear; a search's verdict stage (:mod:`optipose.search.draws`) draws at most
``VerdictConfig.draws`` in ``VerdictConfig.time`` s, and the rules it decides by are the config's
(:meth:`VerdictConfig.rules`): one record of each number, its default said once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from optipose.errors import ConfigError
from optipose.evaluate.objective import StatisticConfig

__all__ = ["Rules", "VerdictConfig"]


@dataclass(frozen=True)
class Rules:
    """How a verdict is reached: the tolerance an axis may be worse by (0.1: 10 %), the share of an axis's scans
    the found layout may fail on beyond the hand one's (0.01: one in a hundred), the intervals' two-sided
    confidence, the bootstrap's replicates and seed, and the objective's statistic (its weights)."""

    tolerance: float = 0.10
    failures: float = 0.01
    confidence: float = 0.95
    replicates: int = 2000
    seed: int = 0
    statistic: StatisticConfig = field(default_factory=StatisticConfig)


@dataclass(frozen=True)
class VerdictConfig:
    """A search's verdict with confidence (:mod:`optipose.search.draws`): draws of the cell after the
    validation's, raced until every k is BUY, KEEP or TIE or ``draws`` are in (and, where a user sets a clock, while
    another draw ends within ``time`` s; 0: none); an axis may be worse by ``tolerance`` (0.1: 10 %) with ``confidence``, and
    found may fail an axis's registration on at most ``failures`` of the scans more than hand (a failed
    registration is a part scanned again: :mod:`optipose.verdict.confidence`)."""

    draws: int = 12
    time: float = 0.0  # s, a clock on the race (0: none; its draws end it)
    # a clock: when above 0, the verdict ends by answer_time s after the search started (0: none)
    answer_time: float = 0.0
    scans: int = 0  # the protocol's scans a draw after the validation's evaluates, drawn by its seed (0: all)
    tolerance: float = Rules.tolerance
    failures: float = Rules.failures
    confidence: float = Rules.confidence
    # the cells each BUY is raced again in, on draws of their own, when the search's cell is one the user did not
    # name (comma-separated cell names; empty: none): its answer then says whether it holds in them
    kinds: str = ""
    kinds_draws: int = 12  # a BUY's draws at most in each of them

    def __post_init__(self) -> None:
        if self.kinds_draws < 1:
            raise ConfigError(f"search verdict: kinds_draws >= 1, not {self.kinds_draws}")
        if (
            self.scans < 0
            or self.draws < 1
            or not 0.5 < self.confidence < 1
            or self.tolerance < 0
            or not 0 <= self.failures < 1
            or self.time < 0
            or self.answer_time < 0
        ):
            raise ConfigError(
                "search verdict: verdict_draws >= 1, verdict_scans >= 0, 0.5 < verdict_confidence < 1, verdict_tolerance >= 0, "
                "0 <= verdict_failures < 1, verdict_time >= 0, answer_time >= 0"
            )

    def rules(self, seed: int, statistic: StatisticConfig) -> Rules:
        """The rules a verdict of this config decides by: its tolerance, failures and confidence, the bootstrap
        seeded by ``seed`` and scored by the objective's ``statistic``."""
        return Rules(
            tolerance=self.tolerance, failures=self.failures, confidence=self.confidence, seed=seed, statistic=statistic
        )
