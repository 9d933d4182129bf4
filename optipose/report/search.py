"""A search's own story: how the surrogate search converged and how well the surrogate ranks layouts
against ICP (the selection's candidates, and the found and baseline layouts' validation)."""

from __future__ import annotations

import numpy as np

from optipose.model.layout import is_part_of
from optipose.report import figures
from optipose.report.document import Block, Figure, Heading, Paragraph

__all__ = ["search_blocks", "surrogate_pairs"]


def surrogate_pairs(selection: list, surrogate: dict, result, label: str) -> list[tuple[str, int, float, float]]:
    """(layout, k, surrogate deg, ICP deg) per layout ICP looked at: the selection's candidates (reduced or
    full protocol) and the found and baseline layouts' validation (not a k the search answered with the baseline's
    own choice: the surrogate's score there is the found layout's it replaced)."""
    pairs = [
        ("candidate", r.k, r.surrogate, float(np.rad2deg(r.choice.score)))
        for r in selection
        if np.isfinite(r.surrogate) and r.origin != "hand"
    ]
    validation = result.validation
    if validation is not None:
        for name, choices in (("found", validation.found), ("hand", validation.baseline)):
            for k, choice in choices.items():
                replaced = name == "found" and k in result.layouts and is_part_of(result.layouts[k], result.baseline)
                if (name, k) in surrogate and not replaced:
                    pairs.append(
                        (name if name == "found" else label, k, surrogate[(name, k)], float(np.rad2deg(choice.score)))
                    )
    return pairs


def search_blocks(history: list, pairs: list, label: str) -> list[Block]:
    """Convergence per k and the surrogate vs. ICP scatter, each where the result has it."""
    blocks: list[Block] = [Heading("The search")]
    if history:
        blocks.append(
            Figure(
                figures.convergence(history),
                "convergence.png",
                "convergence of the surrogate search per k: every feasible evaluation and the best so far",
            )
        )
    if len(pairs) >= 2:
        from scipy.stats import spearmanr

        rho = spearmanr([p[2] for p in pairs], [p[3] for p in pairs]).statistic if len(pairs) > 2 else float("nan")
        blocks.append(
            Figure(
                figures.surrogate_vs_icp(pairs),
                "surrogate_vs_icp.png",
                f"surrogate's predicted score vs. ICP score per layout ICP evaluated ({len(pairs)} layouts; "
                f"Spearman rank correlation {rho:.2f}); found and {label} on the validation protocol",
            )
        )
    else:
        blocks.append(
            Paragraph("no surrogate vs. ICP comparison: fewer than two layouts were evaluated by ICP", "note")
        )
    return blocks
