"""``report.html`` and ``report.md`` for a result folder: :func:`write_report` reads the result with
:func:`optipose.io.load_result` and puts the sections of this package in order, the verdict first.

The HTML is one self-contained file (figures as data URIs, no script or style from elsewhere); the
Markdown references the same figures as PNG files in ``report_figures/``.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path


from optipose.files import write_text
from optipose.report.document import Block, Figure, Heading, Paragraph, render_html, render_markdown, write_figures

__all__ = ["write_report", "build_blocks", "REPORT_HTML", "REPORT_MD", "FIGURE_DIR"]

log = logging.getLogger(__name__)
REPORT_HTML, REPORT_MD, FIGURE_DIR = "report.html", "report.md", "report_figures"


def write_report(folder: str | Path, views: bool = True, ready=None) -> tuple[Path, Path]:
    """Write ``report.html`` and ``report.md`` into a result folder; returns both paths.

    views : draw the 3D views (they scan each layout once at its nominal pose: a few seconds per layout).
    ready : called before the views are taken, last: waits for a search's ``layouts/<name>.png`` being drawn
        beside the report (a view missing then is drawn here).
    """
    folder = Path(folder)
    title, blocks = build_blocks(folder, views, ready)
    html_path, md_path = folder / REPORT_HTML, folder / REPORT_MD
    write_text(html_path, render_html(title, blocks))
    write_figures(blocks, folder / FIGURE_DIR)
    write_text(md_path, render_markdown(title, blocks, FIGURE_DIR))
    return html_path, md_path


def build_blocks(folder: Path, views: bool = True, ready=None) -> tuple[str, list[Block]]:
    """The report's title and blocks for the result in ``folder`` (``ready``: :func:`write_report`'s)."""
    from optipose.io import load_result
    from optipose.io.results import EvaluationResult, RobustnessResult

    result = load_result(folder)
    if isinstance(result, EvaluationResult):
        return _evaluation(folder, result, views)
    if isinstance(result, RobustnessResult):
        return _robustness(folder, result, views)
    return _search(folder, result, views, ready)


def _part(config):
    """The part the result was made for (``config``: its :class:`~optipose.io.config.RunConfig`), or None
    (with a log line) when it cannot be loaded any more."""
    from optipose.errors import OptiposeError
    from optipose.model.part import load_part

    source = config.part
    try:
        return load_part(source, units=config.part_units or "auto")
    except (OptiposeError, OSError) as exc:
        log.warning("report: no 3D views, the part '%s' does not load: %s", source, exc)
        return None


def _views(config, layouts: dict, enabled: bool, drawn: Path | None = None) -> list[Block]:
    """The 3D views (part, heads, fans, keep-outs, a nominal scan's points) of each named layout of the result
    whose :class:`~optipose.io.config.RunConfig` is ``config``; ``drawn``: a folder where a layout's views may
    be drawn already (a search's ``layouts/<name>.png``, by the same function, no older than ``<name>.toml``),
    taken as they are instead of drawn again. The part is loaded only when a view is left to draw."""
    from optipose.report.figures import layout_views

    blocks: list[Block] = [Heading("Where the sensors go")]
    if not enabled:
        return blocks + [Paragraph("3D views left out (--no-views)", "note")]
    pngs = {name: _drawn(drawn, name) for name in layouts}
    if None in pngs.values():  # a view to draw: the part is needed
        part = _part(config)
        if part is None:
            return blocks + [
                Paragraph("no 3D views: the part's file could not be loaded from where the result says it was", "note")
            ]
        shown = replace(part, layouts={**part.layouts, **layouts})
    for name, layout in layouts.items():
        try:
            png = pngs[name] or layout_views(shown, name)
        except Exception as exc:  # a picture must never cost the report
            log.warning("report: could not draw %s: %s", name, exc)
            blocks.append(Paragraph(f"{name}: no picture ({exc})", "note"))
            continue
        blocks.append(
            Figure(
                png,
                f"view_{name}.png",
                f"{name} ({len(layout)} sensor{'s' if len(layout) > 1 else ''}): isometric, front, and close-ups from the "
                "front and the top; heads (boxes), laser fans (dashed), measuring ranges (filled), keep-outs "
                "(dotted) and the points of a nominal scan, one colour per sensor",
            )
        )
    return blocks


def _drawn(folder: Path | None, name: str) -> bytes | None:
    """``folder/<name>.png`` when it was drawn after ``folder/<name>.toml`` was written, else None."""
    if folder is None:
        return None
    png, toml = folder / f"{name}.png", folder / f"{name}.toml"
    if png.is_file() and toml.is_file() and png.stat().st_mtime_ns >= toml.stat().st_mtime_ns:
        return png.read_bytes()
    return None


def _evaluations(sub: Path) -> tuple[object, str]:
    """The evaluation saved in a validation folder, and a note (none); None where there is none."""
    from optipose.io import load_result

    return (load_result(sub), "") if (sub / "config.toml").is_file() else (None, "")


def _search(folder: Path, result, views: bool, ready=None) -> tuple[str, list[Block]]:
    from optipose.io.load import load_history, load_selection, load_surrogate_scores
    from optipose.model.baseline import baseline_label
    from optipose.report.layouts import layout_section
    from optipose.report.provenance import cell_name, provenance_blocks
    from optipose.report.scans import scan_blocks
    from optipose.report.search import search_blocks, surrogate_pairs
    from optipose.report.confidence import confident_blocks
    from optipose.report.verdict import table1_side_by_side, verdict_blocks

    label = baseline_label(result.baseline)
    validation = result.validation
    title = f"{result.part}: where to mount the sensors (search, budget {result.budget}, seed {result.seed})"
    blocks: list[Block] = []
    if validation is None:
        blocks.append(
            Paragraph(
                "the search stopped before its validation: no verdict; the layouts below are its best so far",
                "verdict mixed",
            )
        )
    else:
        protocol = (
            "the full protocol"
            if validation.protocol == "full"
            else "the REDUCED protocol (14 scans; --budget default for the full one)"
        )
        verdict = verdict_blocks(
            result.verdicts(), validation.found, validation.baseline, label, unchecked=result.unchecked
        )
        if result.confident.by_k:  # the verdict on draws decides
            verdict = verdict[:1] + confident_blocks(
                result.confident, cell_name(result.config), result.layouts, result.baseline, result.kinds
            )
        blocks += verdict
        blocks.append(
            Paragraph(
                f"Validated on {protocol} with a held-out noise seed ({validation.seed}); the baseline is the "
                f"{'hand-placed layout' if label == 'hand' else 'conventional placement (the part has no hand-placed layout)'}. "
                + (
                    "The table below is that draw alone, on which each layout's subset per axis was chosen."
                    if result.confident.by_k
                    else "A verdict says 'better in sum' from the summed per-axis medians and 75th percentiles, and 'no worse on "
                    "any axis' only when every one of them is at most the baseline's."
                ),
                "note",
            )
        )
        blocks.append(Heading("Per axis (the paper's Table 1)"))
        blocks.append(
            table1_side_by_side(
                validation.found,
                validation.baseline,
                label,
                "Table 1: median / 75th percentile of |error| in millidegrees, and the sensor subset each axis uses",
            )
        )
    layouts = {f"found_k{k}": lay for k, lay in sorted(result.layouts.items())}
    if result.baseline is not None:
        layouts[label] = replace(result.baseline, name=label)
    at = len(blocks)  # the views go here, taken last (their pictures may still be drawn beside this)
    blocks.append(Heading("Poses for the robot program"))
    for name, layout in layouts.items():
        blocks += layout_section(name, layout)
    if (folder / "validation").is_dir():
        blocks.append(Heading("Errors and points on the validation"))
        for sub in sorted((folder / "validation").iterdir()):
            evaluation, note = _evaluations(sub) if sub.is_dir() else (None, "")
            if evaluation is not None:
                name = label if sub.name == "hand" else sub.name.replace("_k", " k=")
                blocks += scan_blocks(evaluation, name, sub.name, note)
    pairs = surrogate_pairs(load_selection(folder), load_surrogate_scores(folder), result, label)
    blocks += search_blocks(load_history(folder), pairs, label)
    blocks += provenance_blocks(result.config)
    if ready is not None:
        ready()
    blocks[at:at] = _views(result.config, layouts, views, folder / "layouts")
    return title, blocks


def _evaluation(folder: Path, result, views: bool) -> tuple[str, list[Block]]:
    from optipose.verdict.words import mdeg_text
    from optipose.io.folders import read_config
    from optipose.report.layouts import layout_section
    from optipose.report.provenance import provenance_blocks
    from optipose.report.scans import scan_blocks
    from optipose.report.verdict import table1_alone

    n_scans = result.per_scan["scan"].nunique()
    name = result.layout.name
    title = f"{result.part}: layout '{name}' evaluated ({result.objective.name}, {n_scans} scans, seed {result.seed})"
    best = result.table[-1]
    blocks: list[Block] = [
        Heading("Summary"),
        Paragraph(
            f"with all {best.k} sensors the best per-axis choice scores {mdeg_text(best.score)} mdeg (sum of per-axis median and p75); "
            + "; ".join(f"k={c.k}: {c.name} {mdeg_text(c.score)} mdeg" for c in result.table),
            "verdict info",
        ),
    ]
    blocks.append(Heading("Per axis (the paper's Table 1)"))
    blocks.append(
        table1_alone(
            result.table,
            name,
            "Table 1: median / 75th percentile of |error| in millidegrees, and the sensor subset each axis uses",
        )
    )
    config = read_config(folder)
    blocks += _views(config, {name: result.layout}, views)
    blocks.append(Heading("Poses for the robot program"))
    blocks += layout_section(name, result.layout)
    blocks.append(Heading("Errors and points"))
    blocks += scan_blocks(result, name, "evaluation")
    blocks += provenance_blocks(config)
    return title, blocks


def _robustness(folder: Path, result, views: bool) -> tuple[str, list[Block]]:
    from optipose.model.baseline import baseline_label
    from optipose.report.layouts import layout_section
    from optipose.report.provenance import provenance_blocks
    from optipose.report.robustness import holds_blocks, instance_blocks

    label = baseline_label(result.layouts.get("hand"))
    title = f"{result.part}: layouts in cell instances the search never saw (robustness, seed {result.seed})"
    blocks: list[Block] = [Heading("Where the layouts hold")]
    blocks += holds_blocks(result, label) or [
        Paragraph(f"only the {label} layout was evaluated: nothing to compare", "verdict mixed")
    ]
    blocks.append(Heading("In every cell instance"))
    blocks += instance_blocks(result, label)
    layouts = {
        (label if n == "hand" else n): replace(lay, name=label if n == "hand" else n)
        for n, lay in result.layouts.items()
    }
    blocks += _views(result.config, layouts, views)
    blocks.append(Heading("Poses for the robot program"))
    for name, layout in layouts.items():
        blocks += layout_section(name, layout)
    blocks += provenance_blocks(result.config)
    return title, blocks
