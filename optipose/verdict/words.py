"""The verdict in words: every line the terminal, the report and the scripts say about a verdict, and every angle
they show, written here once.

Numbers: :mod:`optipose.verdict.numbers`' (millidegrees, ratios, poses), given here under the same names. Lines: the verdict
with confidence (:func:`confident_line`, :func:`fewer_line`, :func:`axis_lines`, :func:`mount_line`), the
validation draw's verdict (:func:`verdict_line`, :func:`failed_line`,
:func:`verdict_headline`), an axis no found layout measures (:func:`unmeasured_line`), one found sensor against
the baseline's largest choice (:func:`one_versus_many`), and what a verdict holds in (:data:`IDEAL_CELL`,
:data:`UNCHECKED`). The records they read are :mod:`optipose.verdict.confidence`'s and
:mod:`optipose.verdict.compare`'s; each line fits 80 columns where its docstring says so.
"""

from __future__ import annotations

import math


from optipose.evaluate.assignment import UNOBSERVABLE, UNOBSERVABLE_PENALTY, Choice
from optipose.model.layout import kept_sensors
from optipose.verdict.compare import Verdict
from optipose.verdict.confidence import ConfidentVerdict, Decision, at_ends, borne_out, raced_in
from optipose.verdict.numbers import (  # noqa: F401  (given under this module's name too)
    sig_mdeg,
    interval_cell,
    mdeg,
    mdeg_column,
    mdeg_compact,
    mdeg_text,
    one_cell_cell,
    ratio_cell,
    xyz_rpy_text,
)
from optipose.verdict.ruling import FIELDS, MIN_DRAWS

__all__ = [
    "IDEAL_CELL",
    "UNCHECKED",
    "mdeg",
    "mdeg_text",
    "mdeg_compact",
    "mdeg_column",
    "one_cell_cell",
    "interval_cell",
    "ratio_cell",
    "xyz_rpy_text",
    "confident_line",
    "open_line",
    "ruling_line",
    "cell_advice",
    "kinds_line",
    "clock_line",
    "fewer_line",
    "axis_lines",
    "mount_line",
    "verdict_line",
    "failed_line",
    "verdict_headline",
    "unmeasured_line",
    "one_versus_many",
]

# what a verdict with confidence from the ideal cell says it holds in
IDEAL_CELL = (
    "in the ideal cell (the CAD part, an exact robot and calibration): run without --cell ideal, or "
    "with a cell file of yours, for the errors of a real cell before buying"
)

# what the validation draw's verdict of a search in the ideal cell says: better there is not yet a reason to buy
UNCHECKED = (
    "checked in the ideal cell only (the CAD part, an exact robot and calibration), not in a real cell: check it "
    "in the cell you own (optipose robustness --layout ... --cell NAME) before buying"
)


def confident_line(v: ConfidentVerdict) -> str:
    """One line of at most 80 columns: the decision, hand / found in sum with its interval, the draws (and
    under UNDECIDED how many more would settle it; why it is open and in what time: :func:`open_line`), the same
    on any machine for the same draws, e.g.
    ``k=2: BUY F1F3 1.42x [1.21, 1.66] better than hand S1S2 (12 draws)``."""
    ratio, ref = ratio_cell(v.score), f"{v.reference} {v.baseline_name}"
    head = f"k={v.k}: {v.decision}"
    if len(v.unmeasured) == len(v.found):  # equal because neither measures anything: say that
        text = f"k={v.k}: nothing measured: {v.found_name} and {ref} see no {'/'.join(v.unmeasured)}"
        return text if len(text) <= 80 else f"k={v.k}: nothing measured: {v.found_name} and {ref} see no axis"
    tail = f"{v.n_draws} draw{'s' if v.n_draws != 1 else ''}"
    if v.decision == Decision.UNDECIDED and v.more_draws is not None:
        tail += f"; +{v.more_draws}"  # the minutes are the machine's: on the line below (open_line), not here
    if v.decision == Decision.KEEP:
        worse = [a.axis for a in v.axes if a.ratio.high < 1.0 / (1.0 + v.tolerance)]
        fails = [a for a in v.axes if a.failed.low > v.failures]
        why = (f", worse on {'/'.join(worse)}" if worse else "") + "".join(
            f", fails {100 * a.failed.estimate:.1f} % more {a.axis}" for a in fails[:1]
        )
        if not why and v.score.high >= 1.0:  # the futility stop: found cannot gain more than a TIE allows
            why = f", gains under {100 * v.tolerance:.0f} %"
        # the reasons before the ratio where both do not fit
        texts = [
            f"{head} {ref}; {v.found_name} {ratio}{why}",
            f"{head} {ref}; {v.found_name}{why}",
            f"{head} {ref}{why}",
        ]
        text = next(
            (t for t in texts if len(f"{t} ({tail})") <= 80), next((t for t in texts if len(t) <= 80), texts[-1])
        )
    elif v.decision == Decision.BUY:
        text = f"{head} {v.found_name} {ratio} better than {ref}"
    elif v.decision == Decision.TIE and v.kept:
        text = f"{head} keep {ref}: no found layout beat it"  # the search answered with the baseline's own choice
    elif v.decision == Decision.TIE:
        text = f"{head} {v.found_name} {ratio} vs {ref}: keep {v.baseline_name}"
    else:
        text = f"{head} {v.found_name} {ratio} vs {ref}"
    # undecided: the axis whose interval straddles the tolerance, where it fits
    open_ = [a for a in v.axes if a.ratio.low < 1.0 / (1.0 + v.tolerance) <= a.ratio.high]
    axis = "".join(f"; {a.axis} {ratio_cell(a.ratio)}" for a in open_[:1])
    failing = [a for a in v.axes if a.failed.low <= v.failures < a.failed.high]  # found may fail more than allowed
    fails = "".join(f"; {a.axis} fails {100 * a.failed.estimate:+.1f} %" for a in failing[:1])
    axis = (axis or fails) if v.decision == Decision.UNDECIDED else ""
    # the failed share is in no table: it goes before the draws to add where both do not fit
    order = (f"{text}{axis}", f"{text} ({tail})") if axis == fails else (f"{text} ({tail})", f"{text}{axis}")
    fits = [line for line in (f"{text}{axis} ({tail})", *order) if len(line) <= 80]
    return fits[0] if fits else text[:80]


def open_line(v: ConfidentVerdict, most: int = 0) -> str:
    """Why an UNDECIDED verdict is open and what would settle it, one line below its verdict line, e.g.
    ``  k=1 open: the sum 1.11x [0.92, 1.31] spans 1 after the budget's 10 draws; +22 draws would settle it
    (about 4 min here; --budget thorough races 30)``. What keeps it open: the sum's interval spanning 1, an axis's
    spanning the tolerance, or an axis's extra failed registrations spanning theirs. What would settle it: the
    draws (and the minutes at this run's pace), or that no number of draws would at these estimates, or that
    more are needed than ``most`` (the most draws any budget races: nothing within the budgets can). "" for a
    decided verdict."""
    if v.decision != Decision.UNDECIDED:
        return ""
    if v.ended == "ends":  # better across the cell's ranges, not shown at an end of them (optipose.search.kinds)
        return (
            f"  k={v.k} open: {ratio_cell(v.score)} across the cell's ranges, not shown at both of their ends: it "
            "depends on where your cell lies"
            + (
                ", and no one range decides it on the race's draws"
                if v.ruling is None and v.n_draws >= MIN_DRAWS
                else ""
            )
        )
    if v.ended == "kinds":  # better in the objective's cell, which the user did not name, not in every kind
        return (
            f"  k={v.k} open: {ratio_cell(v.score)} in the objective's cell, not shown in every common kind of cell: "
            "it depends on your kind of cell"
        )
    floor = 1.0 / (1.0 + v.tolerance)
    spans = [f"the sum {ratio_cell(v.score)} spans 1"] if v.score.low <= 1.0 <= v.score.high else []
    spans += [
        f"{a.axis} {ratio_cell(a.ratio)} spans {floor:.2f}" for a in v.axes if a.ratio.low < floor <= a.ratio.high
    ]
    spans += [
        f"{a.axis} fails {100 * a.failed.low:+.1f} to {100 * a.failed.high:+.1f} % more, across {100 * v.failures:.0f} %"
        for a in v.axes
        if a.failed.low <= v.failures < a.failed.high
    ]
    what = spans[0] if spans else f"the sum {ratio_cell(v.score)} is neither within {100 * v.tolerance:.0f} % nor clear"
    draws = f"{v.n_draws} draw{'s' if v.n_draws != 1 else ''}"
    ended = {
        "draws": f" after the budget's {draws}",
        "clock": f": the clock ended the race at {draws} (without --max-time the draws end it)",
    }.get(v.ended, f" after {draws}")
    if v.more_draws is None:
        settle = "no number of draws settles it at these estimates"
    elif most and v.n_draws + v.more_draws > most:
        settle = f"+{v.more_draws} draws would settle it, more than any budget races ({most}): none within them can"
    else:
        minutes = v.more_minutes
        pace = (
            (f"about {minutes:.0f} min here" if minutes >= 1 else f"about {60 * minutes:.0f} s here")
            if math.isfinite(minutes)
            else ""
        )
        more = f"--budget thorough races {most}" if most and v.n_draws < most else ""
        settle = f"+{v.more_draws} draws would settle it" + (
            f" ({'; '.join(p for p in (pace, more) if p)})" if pace or more else ""
        )
    return f"  k={v.k} open: {what}{ended}; {settle}"


def ruling_line(v: ConfidentVerdict) -> str:
    """Which magnitude of the cell's ranges decides the verdict and where (:mod:`optipose.verdict.ruling`), one
    line below its verdict line, e.g. ``  k=2 holds for a robot path error above 0.052 mm (...)``; "" when none does."""
    r = v.ruling
    if r is None:
        return ""
    name, unit, factor = FIELDS.get(r.key, (r.key, "", 1.0))
    side, other = ("above", "below") if r.above else ("below", "above")
    at = f"{r.at * factor:.3g}{'' if unit in ('%', 'x') else ' '}{unit}"
    head = {
        Decision.BUY: f"holds for a {name} {side} {at}",
        Decision.KEEP: f"the found layout wins only for a {name} {side} {at}",
    }.get(v.decision, f"depends on the {name}: found better {side} {at}, hand {other}")
    return f"  k={v.k} {head} (the draws' ratio crosses 1 there; {100 * r.share:.0f} % of their spread)"


def cell_advice(name: str) -> str:
    """What a search run in its objective's cell of points (no ``--cell`` named) says under its answer."""
    return (
        f"answered in the objective's cell, {name} (one cell's points); for yours name its kind: --cell cobot, "
        "industrial-arm or linear-axis, or --cell common for any of them (optipose cells)"
    )


def kinds_line(k: int, kinds: dict) -> str:
    """What a search's BUY at ``k`` does in the cells it was raced again in (:mod:`optipose.search.kinds`): the
    common kinds of cell (a search in a cell the user did not name), or the ends of the search's cell's ranges
    (``NAME:low``, ``NAME:high``); ``kinds`` cell → :class:`~optipose.verdict.confidence.Verdicts`; "" for a k not
    raced there."""
    raced = raced_in(k, kinds)
    if not raced:
        return ""
    ends = at_ends(raced)
    held = {name: v for name, v in raced.items() if v.decision == Decision.BUY}
    most = f"(at most {max(v.n_draws for v in raced.values())} draws each)"
    if borne_out(k, kinds):
        where = "at both ends of the cell's ranges" if ends else "in every common kind of cell"
        return (
            f"  k={k} the BUY holds {where}: {', '.join(f'{n} {ratio_cell(v.score)}' for n, v in raced.items())} {most}"
        )
    holds = ", ".join(f"{name} {ratio_cell(v.score)}" for name, v in held.items())
    not_in = ", ".join(
        f"{name} ({v.decision.value} {ratio_cell(v.score)})" for name, v in raced.items() if name not in held
    )
    if ends:
        return (
            f"  k={k} the BUY depends on where your cell lies in its ranges: {f'holds at {holds}; ' if holds else ''}"
            f"not at {not_in} {most}: give your cell's magnitudes (a cell file, or optipose calibrate)"
        )
    return (
        f"  k={k} the BUY depends on your cell: {f'holds in {holds}; ' if holds else ''}not in {not_in} {most}: name "
        "yours with --cell NAME"
    )


def clock_line(cut: tuple[str, ...], seconds: float) -> str:
    """What a user's clock (``--max-time``) ended before its counts, and how to get the seed's own answer; "" when
    it ended nothing."""
    if not cut:
        return ""
    clock = f"the {seconds:g} s clock (--max-time)" if seconds > 0 else "a clock of the search config"
    return (
        f"{clock} ended {', '.join(cut)} before their counts: this answer is the machine's speed's as well as the "
        "seed's; without the clock the seed gives its own, on any machine"
    )


def fewer_line(v: ConfidentVerdict) -> str:
    """The comparison of fewer found sensors with more hand ones (``baseline_k`` > k) in one line of at most 80
    columns, e.g. ``fewer sensors: found F1 alone matches hand S1S2S3 within 10 % (1.02x [0.95, 1.08])``
    (shorter where the names are long: ``fewer: F1 alone matches conventional S1S2S3 within 10 % …``)."""
    ratio, ref = ratio_cell(v.score), f"{v.reference} {v.baseline_name}"
    template = (
        "nothing measured by {who} or {ref}"
        if len(v.unmeasured) == len(v.found)
        else {
            Decision.BUY: "{who} is better than {ref}: {ratio}",
            Decision.KEEP: "{who} does not match {ref} ({ratio})",
            Decision.TIE: "{who} matches {ref} within " + f"{100 * v.tolerance:.0f}" + " % ({ratio})",
        }.get(v.decision, "{who} vs {ref}: {ratio}, not settled")
    )
    found = "" if v.kept else "found "  # the search answered with one of the baseline's own
    lines = [
        f"{head}: " + template.format(who=who, ref=ref, ratio=ratio)
        for head, who in (
            ("fewer sensors", f"{found}{v.found_name} alone"),
            ("fewer sensors", f"{v.found_name} alone"),
            ("fewer", f"{v.found_name} alone"),
        )
    ]
    return next((line for line in lines if len(line) <= 80), lines[-1][:80])


def axis_lines(v: ConfidentVerdict) -> list[str]:
    """Per axis, found's and hand's predicted median / p75 (mdeg) with intervals, each ≤ 80 columns."""
    out = []
    for f, h in zip(v.found, v.baseline):
        cells = [
            f"{sig_mdeg(i.estimate)} [{sig_mdeg(i.low)}, {sig_mdeg(i.high)}]"
            for i in (f.median_deg, h.median_deg, f.p75_deg, h.p75_deg)
        ]
        out.append(f"  {f.axis:5} median found {cells[0]} hand {cells[1]} mdeg")
        out.append(f"  {'':5} p75    found {cells[2]} hand {cells[3]} mdeg")
    return out


def mount_line(v: ConfidentVerdict, found, baseline) -> str:
    """What a BUY asks of the cell, in one line: the found sensors its choice uses that are new (their poses
    follow in the layouts), the baseline's it keeps in their brackets and those it frees, e.g.
    ``k=2: mount F1 (new), keep S2; S1 freed``; "" for another decision. ``found``, ``baseline``: the
    :class:`~optipose.model.layout.Layout` of the found k sensors and the baseline's."""
    if v.decision != Decision.BUY or found is None or baseline is None:
        return ""
    used = [n for n in found.names if n in v.found_name]
    kept = kept_sensors(found, baseline)
    new = [n for n in used if n not in kept]
    keep = [kept[n] for n in used if n in kept]
    freed = [n for n in baseline.names if n in v.baseline_name and n not in keep]
    parts = ([f"mount {', '.join(new)} (new)"] if new else []) + ([f"keep {', '.join(keep)}"] if keep else [])
    return f"k={v.k}: " + ", ".join(parts) + (f"; {', '.join(freed)} freed" if freed else "")


def _mdeg_or_unmeasured(rad: float) -> str:
    return "unmeasured" if rad == UNOBSERVABLE_PENALTY else mdeg_text(rad)


def verdict_line(v: Verdict, reference: str = "hand") -> str:
    """The validation draw's verdict in one line for a terminal or a report: ratio, every worse axis (mdeg), and
    keep or replace; ``reference`` names the baseline (``hand``, ``conventional``). Where registrations failed,
    no ranking: :func:`failed_line`."""
    if failed := failed_line(v, reference):
        return failed
    ratio, name, ref = v.ratio, v.found.name, v.reference.name
    gaps = sorted(v.worse, key=lambda g: g.reference / g.found)  # the widest first
    worse = [
        f"{g.axis} {g.statistic} {_mdeg_or_unmeasured(g.found)} vs {_mdeg_or_unmeasured(g.reference)}" for g in gaps[:3]
    ]
    if len(gaps) > 3:
        worse.append(f"{len(gaps) - 3} more")
    than = f"x {'better' if ratio >= 1 else 'worse'} in sum than {reference} {ref}"
    head = f"k={v.k}: found {name} {ratio if ratio >= 1 else 1 / ratio:.2f}{than}"
    if v.tie:
        return f"k={v.k}: found {name} ties {reference} {ref} on every axis: keep {ref}"
    if worse and ratio < 1:
        return f"{head} and worse on {'; '.join(worse)} mdeg: keep {ref}"
    if worse:
        return f"{head}, but worse on {'; '.join(worse)} mdeg: keep {ref} if no axis may get worse"
    return f"{head}, no worse on any axis"


def failed_line(v: Verdict, reference: str = "hand") -> str:
    """The verdict when registrations failed on some axis of either choice ("" when none did): no ranking, what
    failed and where to look (the mesh of a part that is not a closed solid, most often)."""
    mine, theirs = v.failed
    if not mine and not theirs:
        return ""
    name, ref = v.found.name, v.reference.name
    what = [f"the registrations of found {name} failed on {', '.join(mine)}"] if mine else []
    what += [f"those of {reference} {ref} on {', '.join(theirs)}"] if theirs else []
    then = f"keep {ref} until they succeed" if mine else f"found {name} is not shown better there"
    return (
        f"k={v.k}: no verdict: {' and '.join(what)} in over a tenth of the scans (see per_scan.csv's failure "
        f"column; is the part's mesh a closed solid?): {then}"
    )


def verdict_headline(v: Verdict, label: str = "hand", checked: bool = True) -> str:
    """The verdict for one k in one short line (under 80 characters for the hand layout and names up to 6): buy
    or keep (:func:`optipose.verdict.compare.bought`). ``checked=False``: the search ran in the ideal cell, so a
    layout no worse there is better there, not yet bought.
    Where registrations failed on some axis of either layout: no verdict, and whose."""
    ratio, found, ref = v.ratio, v.found.name, v.reference.name
    mine, theirs = v.failed  # registrations failed on some axis: nothing to rank (failed_line says more)
    if mine or theirs:
        who = f"found {found}" if mine else f"{label} {ref}"
        return f"k={v.k}: NO VERDICT: registrations of {who} failed ({', '.join(mine or theirs)})"
    if v.tie:
        return f"k={v.k}: KEEP {label} {ref}: found {found} ties it on every axis"
    if v.no_worse and not checked:
        return f"k={v.k}: found {found} {ratio:.2f}x better, no axis worse, in the ideal cell"
    if v.no_worse:
        return f"k={v.k}: BUY found {found}: {ratio:.2f}x better in sum than {label} {ref}, no axis worse"
    if ratio < 1:
        return f"k={v.k}: KEEP {label} {ref}: found {found} is {1 / ratio:.2f}x worse in sum"
    axes = ", ".join(dict.fromkeys(g.axis for g in v.worse))
    return f"k={v.k}: found {found} {ratio:.2f}x better in sum than {label} {ref}, worse on {axes}"


def unmeasured_line(k: int, found: Choice, reference: Choice | None = None, label: str = "hand") -> str:
    """One line when the found choice of k sensors measures some axis with none of its subsets ("" when it
    measures all three): the axes no found layout of k sensors observes, and those whose registrations
    failed too often — their error is unknown, not small — and whether the reference (``label``) does."""
    out = []
    for reason in dict.fromkeys(a.reason for a in found.axes if not a.observable):
        axes = [a.axis for a in found.axes if not a.observable and a.reason == reason]
        names = " and ".join(axes)
        theirs = [a for a in (reference.axes if reference is not None else ()) if a.axis in axes]
        also = ""
        if theirs:
            seen = [a.axis for a in theirs if a.observable]
            also = (
                f"; {label} {reference.name} does not either"
                if not seen
                else f"; {label} {reference.name} measures {' and '.join(seen)}"
            )
        if reason == UNOBSERVABLE:
            sensors = f"{k} sensor{'s' if k > 1 else ''}"
            out.append(
                f"{names} unobservable: no layout of {sensors} the search found observes {'it' if len(axes) == 1 else 'them'}{also}"
            )
        else:
            out.append(
                f"{names} not measured: the registrations of found {found.name} that observe {'it' if len(axes) == 1 else 'them'} "
                f"failed in over a tenth of the scans{also}"
            )
    return f"k={k}: " + "; ".join(out) + " (the error is unknown, not small)" if out else ""


def one_versus_many(one: Choice, many: Choice, reference: str = "hand-placed", the: bool = True) -> str:
    """Whether one found sensor beats the reference's largest choice in sum: fewer sensors to buy, e.g. ``one
    found sensor beats the hand-placed S1S2S3 in sum (0.800 vs 0.900 mdeg)`` (without "the": ``the=False``)."""
    beats = one.score < many.score
    return (
        f"one found sensor {'beats' if beats else 'does not beat'} {'the ' if the else ''}{reference} {many.name} "
        f"in sum ({mdeg_text(one.score)} vs {mdeg_text(many.score)} mdeg)"
    )
