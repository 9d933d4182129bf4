"""The report's charts as PNG bytes (matplotlib, Agg): per-axis error per sensor subset (the paper's
Figures 5–7), points per scan and sensor (Figure 9), the search's convergence, surrogate vs. ICP, found
vs. baseline per condition of a band, and the 3D views of :mod:`optipose.report.views`.

Every function takes records (or the frames a record carries) and returns PNG bytes; angles in the
pictures are millidegrees, as in the terminal tables.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["subset_boxplots", "point_counts", "convergence", "surrogate_vs_icp", "condition_bars", "layout_views"]

_AXES = ("roll", "pitch", "yaw")
_DPI = 100


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=_DPI)
    _plt().close(fig)
    return buf.getvalue()


def subset_boxplots(per_scan, title: str) -> bytes:
    """|error| per axis (mdeg, log scale) for every sensor subset: one panel per axis, one box per subset.

    per_scan : an EvaluationResult's per-scan table (``subset``, ``ok``, ``err_roll`` … in rad).
    """
    plt = _plt()
    subsets = list(dict.fromkeys(per_scan["subset"]))
    ok = per_scan[per_scan["ok"].astype(bool)]
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), sharey=True)
    for ax, axis in zip(axes, _AXES):
        data = [np.abs(ok.loc[ok["subset"] == s, f"err_{axis}"].to_numpy()) * 1e3 * 180 / np.pi for s in subsets]
        data = [np.clip(d, 1e-4, None) if len(d) else np.array([np.nan]) for d in data]
        ax.boxplot(data, showfliers=True, flierprops={"markersize": 2}, medianprops={"color": "C3"})
        ax.set_xticks(range(1, len(subsets) + 1), subsets, rotation=45 if len(subsets) > 4 else 0, fontsize=9)
        ax.set_yscale("log")
        ax.set_title(axis)
        ax.grid(axis="y", alpha=0.3, which="both")
    axes[0].set_ylabel("|error| (mdeg, log)")
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    return _png(fig)


def point_counts(points, title: str) -> bytes:
    """Points per scan and sensor after down-sampling (the paper's Figure 9).

    points : an EvaluationResult's points table (``scan``, ``sensor``, ``n_points``, ``n_points_down``).
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(13, 3.4))
    for i, (sensor, group) in enumerate(points.groupby("sensor", sort=False)):
        group = group.sort_values("scan")
        ax.plot(group["scan"], group["n_points_down"], "-o", ms=2.5, lw=1, color=f"C{i}", label=f"{sensor} (voxels)")
    ax.set_xlabel("scan")
    ax.set_ylabel("points after down-sampling")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=9, ncol=6, loc="best")
    ax.set_title(title, fontsize=11)
    fig.tight_layout()
    return _png(fig)


def convergence(history) -> bytes:
    """The surrogate search per k: every feasible evaluation (dots) and the best so far (line), mdeg, log.

    history : :class:`~optipose.search.records.Evaluation` records in order.
    """
    plt = _plt()
    fig, ax = plt.subplots(figsize=(13, 3.8))
    ks = sorted({e.k for e in history})
    for i, k in enumerate(ks):
        mine = [e for e in history if e.k == k]
        feasible = [(e.number, e.value) for e in mine if e.feasible and np.isfinite(e.value)]
        best = [(e.number, e.best) for e in mine if np.isfinite(e.best)]
        if feasible:
            n, v = np.array(feasible).T
            ax.scatter(n, v * 1e3, s=5, color=f"C{i}", alpha=0.35)
        if best:
            n, v = np.array(best).T
            ax.plot(n, v * 1e3, color=f"C{i}", lw=2, label=f"k={k}: best so far {1e3 * v[-1]:.3f} mdeg")
    n_bad = sum(not e.feasible for e in history)
    ax.set_yscale("log")
    finals = {}
    for e in history:  # the best value reached per k
        if np.isfinite(e.best):
            finals[e.k] = min(finals.get(e.k, np.inf), e.best)
    if finals:  # early penalised values would squash the part worth seeing
        ax.set_ylim(0.8e3 * min(finals.values()), 50e3 * max(finals.values()))
    ax.set_xlabel(f"surrogate evaluation ({len(history)} in all, {n_bad} infeasible not drawn)")
    ax.set_ylabel("predicted score (mdeg)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=9)
    fig.tight_layout()
    return _png(fig)


def surrogate_vs_icp(pairs: list[tuple[str, int, float, float]]) -> bytes:
    """How well the surrogate ranks layouts: (label, k, surrogate deg, ICP deg) per layout, log–log, mdeg."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 5.2))
    markers = {"found": "o", "hand": "s", "conventional": "s"}
    for label in dict.fromkeys(p[0] for p in pairs):
        for k in sorted({p[1] for p in pairs if p[0] == label}):
            pts = np.array([(p[2], p[3]) for p in pairs if p[0] == label and p[1] == k]) * 1e3
            ax.scatter(
                pts[:, 0],
                pts[:, 1],
                marker=markers.get(label, "^"),
                color=f"C{k - 1}",
                s=40,
                alpha=0.8,
                label=f"{label} k={k}",
                edgecolor="k",
                linewidth=0.4,
            )
    values = np.array([(p[2], p[3]) for p in pairs]) * 1e3
    if len(values):
        lo, hi = values.min() / 1.5, values.max() * 1.5
        ax.plot([lo, hi], [lo, hi], color="0.6", lw=1, ls="--", label="ICP = surrogate")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("surrogate's predicted score (mdeg)")
    ax.set_ylabel("ICP score (mdeg)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return _png(fig)


def condition_bars(rows: list[tuple[str, float, float]], baseline: str, title: str) -> bytes:
    """Found vs. baseline score (mdeg) in every cell instance: rows of (instance, found, baseline) rad."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(rows) + 3), 3.6))
    x = np.arange(len(rows))
    found = np.array([r[1] for r in rows]) * 1e3 * 180 / np.pi
    base = np.array([r[2] for r in rows]) * 1e3 * 180 / np.pi
    ax.bar(x - 0.2, base, 0.4, color="0.65", label=baseline)
    ax.bar(x + 0.2, found, 0.4, color="C0", label="found")
    labels = [r[0].replace(", ", ",\n") for r in rows]  # "cobot, low ends" on two lines: no overlap
    ax.set_xticks(x, labels, fontsize=9, rotation=20 if len(rows) > 4 else 0)
    ax.set_ylabel("score (mdeg)")
    ax.set_title(title, fontsize=11)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=9)
    fig.tight_layout()
    return _png(fig)


def layout_views(part, layout_name: str) -> bytes:
    """The 3D views of :func:`optipose.report.views.render_part` (isometric, front, close-ups from the front
    and the top: part, heads, fans, keep-outs and a nominal scan's points) as PNG bytes."""
    from optipose.report.views import render_part

    with tempfile.TemporaryDirectory() as tmp:
        path = render_part(part, Path(tmp) / "view.png", layout_name)
        return path.read_bytes()


def verdict_intervals(verdicts: list) -> bytes:
    """Per axis (a panel each) and k, the predicted median |error| in the cell (mdeg, log) of the found layout
    and the baseline, each with its interval; ``verdicts``: :class:`~optipose.verdict.confidence.ConfidentVerdict`."""
    plt = _plt()
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharey=True)
    ks = [v.k for v in verdicts]
    for j, ax in enumerate(axes):
        for shift, side, colour in ((-0.12, "found", "C0"), (0.12, "baseline", "C1")):
            est = [1e3 * getattr(v, side)[j].median_deg.estimate for v in verdicts]
            low = [1e3 * getattr(v, side)[j].median_deg.low for v in verdicts]
            high = [1e3 * getattr(v, side)[j].median_deg.high for v in verdicts]
            err = np.clip([np.subtract(est, low), np.subtract(high, est)], 0.0, None)
            label = "found" if side == "found" else (verdicts[0].reference if verdicts else "hand")
            ax.errorbar(np.add(ks, shift), est, yerr=err, fmt="o", color=colour, capsize=4, label=label)
        ax.set_xticks(ks, [f"k={k}" for k in ks])
        ax.set_yscale("log")
        ax.set_title(f"{_AXES[j]}: median |error|")
        ax.grid(axis="y", alpha=0.3, which="both")
    axes[0].set_ylabel("predicted (mdeg, log)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    return _png(fig)
