"""``optipose search`` as a pipeline: its stages in order, each result on disk as soon as it exists.

1. the config goes to the result folder first, so even an interrupted run explains itself; a resumed run
   reloads the per-sensor cache and replays its earlier evaluations for free (same seed, same sequence);
2. the NLopt search on the surrogate (:mod:`optipose.search.surrogate_search`: screen, greedy, joint), the
   history and cache flushed to the folder as it goes, the surrogate's best layouts written at its end;
3. the ICP selection, polish and confirmation (:mod:`optipose.search.select`), after which the finalists
   replace the surrogate's best;
4. validation on a noise seed the search never saw (:mod:`optipose.search.validate`): the numbers reported.
   The ``quick`` budget validates on the reduced protocol (14 of the paper's 77 scans) with the same held-out
   seed, so it answers within a minute; the table says so;
5. pictures of the found layouts.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

from optipose.errors import OptiposeError
from optipose.io import search as folder_io
from optipose.model.layout import Layout, SensorPose
from optipose.search.config import SearchConfig
from optipose.search.problem import SurrogateProblem
from optipose.search.records import Found, SearchOutcome, Validation
from optipose.search.space import SPACE_VERSION
from optipose.search.study import SurrogateStudy
from optipose.search.surrogate_search import run_search
from optipose.seeds import validation_seed

__all__ = ["SearchReport", "run", "found_layout", "NoFeasibleLayout"]

log = logging.getLogger(__name__)
_FLUSH_EVERY = 100  # evaluations between writes of the history and the cache


class NoFeasibleLayout(OptiposeError):
    """The search met no layout that satisfies the constraints (e.g. the sensors cannot see the part)."""


@dataclass
class SearchReport:
    """A search run: its folder, the surrogate's outcome, the layouts found per k and their validation."""

    folder: Path
    outcome: SearchOutcome
    layouts: dict[int, Layout] = field(default_factory=dict)
    validation: Validation | None = None

    @property
    def validated(self) -> bool:
        return self.validation is not None


def run(part, objective, config: SearchConfig, seed: int, folder: Path, budget: str = "default",
        jobs: int = 1, resume: bool = False, on_eval=None, on_stage=None) -> SearchReport:  # fmt: skip
    """Search, validate and write everything to ``folder``. ``on_eval(evaluation)`` follows the surrogate
    search; ``on_stage(text)`` is told when a stage starts."""
    stage = on_stage or (lambda text: None)
    folder.mkdir(parents=True, exist_ok=True)
    folder_io.write_search_config(folder, part, objective, config, budget, seed, validation_seed(seed))
    study = _study(part, objective, config, folder, resume, on_eval)
    stage("searching on the surrogate")
    outcome = run_search(part, objective, config, seed, study)
    _flush(folder, study)
    if not outcome.found:
        raise NoFeasibleLayout(
            f"no feasible layout for '{part.name}': in {len(outcome.history)} evaluations no sensor pose returned "
            f"{config.min_points} points without its head hitting the part or a keep-out (can the sensors see "
            f"this part at all? check --units, the material and the part's size against the {config.clearance * 1e3:.0f} mm clearance)"
        )
    hand = part.layouts.get("hand")
    report = SearchReport(folder, outcome, _layouts(outcome.found))
    folder_io.write_layouts(folder, report.layouts, hand)  # the surrogate's best, on disk before anything slower
    if config.select_candidates > 0 and not outcome.interrupted:
        from optipose.search.select import select_finalists

        stage("selecting finalists by ICP on a reduced protocol")
        finalists, records = select_finalists(
            part, objective, outcome, study, seed, config.select_candidates, config.select_time, on_stage, jobs
        )
        folder_io.write_selection(folder, records)
        report.layouts = _layouts({**outcome.found, **finalists})
        folder_io.write_layouts(folder, report.layouts, hand)
    folder_io.write_surrogate_scores(folder, outcome)
    if outcome.interrupted:
        return report
    from optipose.search.validate import validate

    stage(f"validating on the {config.validation} protocol (held-out noise seed)")
    report.validation = validate(part, objective, report.layouts, seed, jobs, config.validation)
    folder_io.write_validation(folder, report.validation)
    _pictures(report, part)
    return report


def _study(part, objective, config, folder: Path, resume: bool, on_eval) -> SurrogateStudy:
    """The live search, with the cache of the folder when resuming, flushing to the folder as it goes."""
    cache = folder_io.load_cache(folder, SPACE_VERSION) if resume else {}
    if resume:
        log.info("resuming with %d cached sensor poses", len(cache))
    study = SurrogateStudy(SurrogateProblem(part, objective, config, cache=cache))
    if on_eval:
        study.callbacks.append(on_eval)
    flushed = [0]

    def flush(_evaluation) -> None:
        if len(study.history) - flushed[0] >= _FLUSH_EVERY:
            _flush(folder, study)
            flushed[0] = len(study.history)

    study.callbacks.append(flush)
    return study


def _flush(folder: Path, study: SurrogateStudy) -> None:
    """History and cache to disk: what was computed is never lost."""
    folder_io.write_history(folder, study.history)
    folder_io.save_cache(folder, study.problem.cache, SPACE_VERSION)


def _layouts(found: dict[int, Found]) -> dict[int, Layout]:
    return {k: found_layout(f) for k, f in found.items()}


def found_layout(found: Found) -> Layout:
    """A found layout as a :class:`Layout` of sensors F1 … Fk, named ``found_k<k>``."""
    sensors = tuple(SensorPose(f"F{i + 1}", T) for i, T in enumerate(found.poses))
    return Layout(sensors, name=f"found_k{found.k}",
                  description=f"found by the {found.strategy} search, surrogate score {found.score:.5f} deg")  # fmt: skip


def _pictures(report: SearchReport, part) -> None:
    """``layouts/found_k*.png`` beside the TOML files: each found layout drawn as ``optipose show`` does."""
    from optipose.report.views import render_part

    shown = replace(part, layouts={**part.layouts, **{f"found_k{k}": lay for k, lay in report.layouts.items()}})
    for k in report.layouts:
        try:
            render_part(shown, report.folder / "layouts" / f"found_k{k}.png", f"found_k{k}")
        except Exception as exc:  # a picture must never cost the results
            log.warning("could not draw found_k%d: %s", k, exc)
