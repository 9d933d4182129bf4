"""How to search: :class:`SearchConfig` and the budgets that fill in its numbers.

Every stage of :mod:`optipose.search` reads its settings from one frozen config; a result folder saves
it (``config.toml``, table ``search``) so ``--resume`` continues with the same one.
"""

from __future__ import annotations

from dataclasses import dataclass

from optipose.errors import ConfigError
from optipose.model.collision import DEFAULT_MARGIN

__all__ = ["SearchConfig", "BUDGETS", "BAND_BUDGETS", "CELL_BUDGETS", "config_from_budget", "algorithm_code"]


@dataclass(frozen=True)
class SearchConfig:
    """How to search. Budgets (``quick``, ``default``, ``thorough``) fill in the numbers."""

    global_algorithm: str = "GN_DIRECT_L"  # best of five on all four problems: benchmarks/README.md
    local_algorithm: str = "LN_BOBYQA"
    global_evals: int = 300  # per greedy stage
    local_evals: int = 120  # per local polish
    joint_evals: int = 200  # per joint polish (k >= 2)
    max_time: float = 600.0  # s, the whole surrogate search
    sensors: tuple[int, ...] = (1, 2, 3)
    strategy: str = "both"  # greedy | joint | both
    min_points: int = 2000
    clearance: float = DEFAULT_MARGIN  # m, head to swept part / keep-outs
    head_gap: float = 0.0  # m, head to head
    margin: float = 0.005  # m, how far outside the part's box the aim point may go
    alpha_max_deg: float = 60.0
    # the laser line may turn at most this far from across the motion (the angle between the line and the
    # plane normal to the scan axis): a line turned toward the motion re-scans its own strip, covers less
    # of the part across the motion, and fools the surrogate (docs/method.md, "Constraints"); 90 turns the
    # constraint off
    line_skew_max_deg: float = 60.0
    random_starts: int = 8  # extra random start points scored before each greedy stage
    # before each greedy stage: score this many space-filling (scrambled Sobol) poses of the new sensor on the
    # surrogate, and polish the best screen_starts distinct ones locally (screen_evals each). DIRECT-L
    # refines around one basin; the screen finds the others, which the ICP selection then compares (quick,
    # which has none, takes the surrogate's best of them)
    screen_samples: int = 0
    screen_starts: int = 6
    screen_evals: int = 30
    select_candidates: int = 3  # per k, candidates re-ranked by ICP on a reduced protocol (0: skip)
    select_time: float = 300.0  # s, the selection stage
    # the hand-anchored candidates' found sensors moved by this many local surrogate evaluations with the
    # kept hand sensors fixed, before the selection evaluates them (0: taken as found; search/candidates.py)
    anchor_evals: int = 0
    # a layout is asked to beat the hand-placed one on every axis, not just on the sum: each axis whose
    # predicted score exceeds hand_margin x the hand-placed k-subset's adds hand_weight x the excess
    # (0 turns it off; < 1 leaves room for the surrogate's error)
    hand_margin: float = 0.5
    hand_weight: float = 5.0
    # the ICP polish of a finalist that is not yet no worse than the hand layout on every axis (search/polish.py)
    polish_algorithm: str = "LN_COBYLA"
    polish_evals: int = 0  # evaluations for k = 1 (half for larger k); 0: no polish
    polish_time: float = 150.0  # s per k, a safety net: the evaluations should end the polish
    polish_margin: float = 0.9  # aim below 0.9 x the hand layout's per-axis statistics
    polish_weight: float = 5.0  # cost per unit of per-axis excess over polish_margin x the hand's, on top of the sum
    polish_step: float = 0.03  # initial step in [0, 1] units (about 2 mm of aim point, 4 deg of view)
    # a finalist that beats the hand layout on the reduced protocol by less than polish_margin on some axis
    # or clear_ratio in sum, or that a polish produced, is confirmed: the best confirm_candidates of that k
    # and the one closest to dominance re-run the full protocol (selection seed) and the best there is
    # kept (0: no confirmation)
    confirm_candidates: int = 0
    clear_ratio: float = 0.4
    validation: str = "full"  # the held-out seed's protocol: full (the objective's) | reduced (end angles only)
    # after the validation, the found layouts and the hand one again on the held-out seed under the
    # [conditions] of this objective (a shipped name or a TOML path; "": no check): a layout that wins only
    # at the preset's noise with perfect brackets is not bought. Skipped when the search's own objective
    # has a band (its validation is under it already)
    band: str = ""
    # the verdict with confidence (search/draws.py): draws of the cell after the validation's, raced until
    # every k is BUY, KEEP or TIE, at most verdict_draws in all and while another draw ends within verdict_time
    # s (0: no limit); an axis may be worse by verdict_tolerance (0.1: 10 %) with verdict_confidence
    verdict_draws: int = 12
    verdict_time: float = 120.0
    # and, when above 0, ends by answer_time s after the search started (its surrogate's set-up), whatever the
    # stages before it took: a budget that promises an answer in so many seconds keeps it on a slower machine
    answer_time: float = 0.0
    verdict_scans: int = 0  # the protocol's scans a draw after the validation's evaluates, drawn by its seed (0: all)
    verdict_tolerance: float = 0.10
    # and found may fail an axis's registration on at most this share of scans more than hand (a failed
    # registration is a part scanned again: verdict/confidence.py)
    verdict_failures: float = 0.01
    verdict_confidence: float = 0.95

    def __post_init__(self) -> None:
        if not self.sensors or min(self.sensors) < 1 or max(self.sensors) > 6:
            raise ConfigError("--sensors: give sensor counts between 1 and 6, e.g. 1,2,3")
        if self.validation not in ("full", "reduced"):
            raise ConfigError(f"search validation must be full or reduced, not '{self.validation}'")
        if self.strategy not in ("greedy", "joint", "both"):
            raise ConfigError(f"search strategy must be greedy, joint or both, not '{self.strategy}'")
        if (
            self.verdict_scans < 0
            or self.verdict_draws < 1
            or not 0.5 < self.verdict_confidence < 1
            or self.verdict_tolerance < 0
            or not 0 <= self.verdict_failures < 1
            or self.verdict_time < 0
            or self.answer_time < 0
        ):
            raise ConfigError(
                "search verdict: verdict_draws >= 1, verdict_scans >= 0, 0.5 < verdict_confidence < 1, verdict_tolerance >= 0, "
                "0 <= verdict_failures < 1, verdict_time >= 0, answer_time >= 0"
            )
        for name in (self.global_algorithm, self.local_algorithm, self.polish_algorithm):
            algorithm_code(name)  # raises ConfigError for an unknown name


BUDGETS: dict[str, dict] = {
    # quick: greedy only, so the layouts are nested and one evaluation validates k = 1, 2, 3 (the hand
    # layout's runs beside the search); a small screen finds basins DIRECT-L's 70 evaluations miss (docs/method.md,
    # "Budgets"); no check under the band, so its verdicts say they hold in the ideal cell only
    "quick": dict(
        global_evals=70,
        local_evals=20,
        max_time=25.0,
        random_starts=4,
        select_candidates=0,
        strategy="greedy",
        screen_samples=1024,
        screen_starts=4,
        screen_evals=20,
        verdict_draws=1,
    ),
    "default": dict(
        global_evals=400,
        local_evals=120,
        joint_evals=200,
        max_time=240.0,
        select_candidates=3,
        select_time=240.0,
        polish_evals=90,
        confirm_candidates=3,
        screen_samples=4096,
        band="robust",
        verdict_time=60.0,
    ),
    "thorough": dict(
        global_evals=2000,
        local_evals=400,
        joint_evals=1000,
        max_time=3000.0,
        random_starts=16,
        screen_samples=16384,
        screen_starts=12,
        screen_evals=60,
        select_candidates=6,
        select_time=1800.0,
        polish_time=900.0,
        polish_evals=200,
        confirm_candidates=6,
        band="robust",
        verdict_draws=30,
        verdict_time=900.0,
    ),
}


# Under a band of conditions every ICP evaluation runs each condition of the band's ends (4 for
# objectives/robust.toml, each more work than a nominal condition: bracket errors slow ICP): the default budget then
# spends its ICP work on the selection and the validation over the band, not on a polish and a
# confirmation; the selection's statistic already pools every condition's scans (docs/conditions.md, "The search
# under the band").
BAND_BUDGETS: dict[str, dict] = {
    # a sensor pose costs the band's surrogate several nominal ones (the noise and bracket terms): 4,096 screen
    # poses would take the whole clock, and k = 1 and 2 got no greedy stage at all
    "default": dict(
        max_time=180.0, select_time=100.0, polish_evals=0, confirm_candidates=0, screen_samples=1024, anchor_evals=80
    ),
}


# In a real cell (an objective's cell other than the ideal one) an ICP evaluation costs several nominal ones
# (the cell's sources move every point; the paper's pipeline removes outliers) and the verdict's draws, not a
# confirmation on one seed, say how sure a difference is: no ICP polish or confirmation, less surrogate search; no
# check under the band, whose noise and brackets the cell's sources stand for. The verdict's draws after the
# validation's evaluate a share of the protocol's scans each: in a real cell the spread between cell instances rules
# the intervals, so more draws of fewer scans decide sooner. The stages end by their evaluations, candidates and
# draws, whose counts are set so that `default` answers within three minutes on two cores and `quick`, validated on
# the reduced protocol's 14 scans, within 30 s (benchmarks/README.md, "Whole commands"); their clocks are safety
# nets for a slower machine, so that on this one a seed gives the same layouts.
CELL_BUDGETS: dict[str, dict] = {
    # quick: a screen of 64 poses (a cell pose costs the surrogate several nominal ones), its three best polished,
    # then per sensor a local BOBYQA from the best start and its polish, few enough evaluations that BOBYQA mostly
    # probes each of the six numbers around its start: DIRECT-L's evaluations went to the surrogate's optimistic
    # corners, and ICP rated the local stage's layouts better (docs/results.md, "`--budget quick` in the real
    # cell"). The verdict's draws of 6 scans each (3 a worker on two cores), so that its seconds see several times
    # as many cell instances as draws of the reduced protocol's 14 scans would (benchmarks/README.md,
    # "bench_verdict_draw.py"); the race plans its looks for as many draws as its seconds hold, each look a share of
    # the error rate. Its seconds are what is left of 23 s after the search started, so that with the start-up, the
    # pictures and the report the answer comes in 30 s on two cores with a second to spare for a shared machine's
    # swings: the draws, unlike the layouts, are the clock's where the seconds hold fewer than the cap
    "quick": dict(
        max_time=15.0,
        screen_samples=64,
        screen_starts=3,
        screen_evals=15,
        global_algorithm="LN_BOBYQA",
        global_evals=20,
        local_evals=10,
        validation="reduced",
        verdict_draws=12,
        verdict_time=12.0,
        verdict_scans=6,
        answer_time=23.0,
    ),
    # default: the joint stage's 100 evaluations, where its clock used to stop it; the race at most 10 draws of 20
    # scans each, which its seconds hold with room, so that the looks are planned for the same draws on every run
    "default": dict(
        max_time=150.0,
        joint_evals=100,
        screen_samples=1024,
        select_time=45.0,
        polish_evals=0,
        confirm_candidates=0,
        band="",
        verdict_scans=20,
        verdict_draws=10,
        verdict_time=60.0,
    ),
    "thorough": dict(band="", verdict_scans=20),
}


def config_from_budget(
    budget: str, sensors: tuple[int, ...], overrides: dict | None = None, band: bool = False, cell: bool = False
) -> SearchConfig:
    """The config of a named budget for these sensor counts, with ``overrides`` (``[search]`` keys) on top;
    ``band``: the objective has a band of conditions (:data:`BAND_BUDGETS` adjusts the budget first);
    ``cell``: it runs in a real cell (:data:`CELL_BUDGETS`, after the band's)."""
    if budget not in BUDGETS:
        raise ConfigError(f"unknown budget '{budget}' (use {', '.join(BUDGETS)})")
    adjusted = {**(BAND_BUDGETS.get(budget, {}) if band else {}), **(CELL_BUDGETS.get(budget, {}) if cell else {})}
    return SearchConfig(sensors=sensors, **{**BUDGETS[budget], **adjusted, **(overrides or {})})


def algorithm_code(name: str) -> int:
    """NLopt's code of a derivative-free algorithm named like ``GN_DIRECT_L``; ConfigError otherwise."""
    import nlopt

    value = getattr(nlopt, name, None)
    if not isinstance(value, int) or not name[:3] in ("GN_", "LN_", "GD_", "LD_", "G_M", "AUG"):
        raise ConfigError(f"unknown NLopt algorithm '{name}' (e.g. GN_CRS2_LM, GN_DIRECT_L, GN_ISRES, LN_BOBYQA)")
    if name.startswith(("GD_", "LD_")):
        raise ConfigError(f"NLopt algorithm '{name}' needs gradients; the objective has none (use GN_*/LN_*)")
    return value
