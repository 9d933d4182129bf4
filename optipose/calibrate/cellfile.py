"""The calibrated cell file: the prior's file with each calibrated range narrowed to the posterior's central 90 %
(docs/calibration.md).

Each calibrated key becomes ``[5 %, 95 %]`` of its posterior (file units, three significant digits), or a point
(the posterior's median) where the data pin it (95 % / 5 % under :data:`PINNED`); a posterior piled against an end of
its prior (its 10 % within the lowest tenth of the prior's draw, or its 90 % within the highest) keeps that end, a
one-sided 90 % (``[prior low, 90 %]``: a cell at the end of a bracket is inside its calibrated range); a range that was
uniform from 0 stays
``[0, 95 %]`` when its 5 % is under a tenth of its 95 % (a log-uniform draw from a tiny low end would put most
instances near it, which the posterior does not). Its ``*_source`` says where it came from. The keys the emulator
does not calibrate (:attr:`optipose.calibrate.emulator.Emulator.fixed`) and every point keep the prior's value and
source. The file loads with ``--cell my_cell.toml``.
"""

from __future__ import annotations

import datetime
import re
import tomllib
from pathlib import Path

from optipose.calibrate.calibration import Calibration
from optipose.cell.config import file_key
from optipose.cell.ranges import middle

__all__ = ["PINNED", "calibrated_text", "narrowed", "write_cell"]

PINNED = 1.1  # a posterior's 95 % / 5 % below this is a point
_EDGE = 0.1  # a posterior whose 10 % (90 %) lies within this share of its prior's draw from an end keeps the end


def narrowed(calibration: Calibration, key: str) -> tuple[float, float, str]:
    """A calibrated key's new range (SI) and how it was taken: ``(low, high, "posterior 5-95 %")``, equal ends for
    a point (``"posterior median (pinned)"``), or a one-sided 90 % that keeps a prior's end."""
    post = calibration.posterior
    lo, hi = post.interval(key)
    if hi <= PINNED * lo:
        point = post.interval(key, 0.5, 0.5)[0]
        return point, point, "posterior median (pinned: 5-95 % within 10 %)"
    prior_low, prior_high = next((low, high) for name, low, high in calibration.prior.ranges if name == key)
    j = post.keys.index(key)
    at_low, at_high = post.quantile_u(j, 0.1) < _EDGE, post.quantile_u(j, 0.9) > 1 - _EDGE
    if at_low and at_high:
        return prior_low, prior_high, "posterior 5-95 % as wide as the prior: kept"
    if at_low:  # piled against the prior's low end: a one-sided 90 % that keeps it
        return prior_low, post.interval(key, 0.9, 0.9)[0], "posterior 0-90 % (piled at the prior's low end)"
    if at_high:
        return post.interval(key, 0.1, 0.1)[0], prior_high, "posterior 10-100 % (piled at the prior's high end)"
    if prior_low == 0 and lo < 0.1 * hi:
        return 0.0, hi, "posterior 5-95 %, from 0 as its prior"
    return lo, hi, "posterior 5-95 %"


def calibrated_text(calibration: Calibration, name: str) -> str:
    """The calibrated cell file's text, named ``name``."""
    import tomli_w

    prior = calibration.prior
    table = tomllib.loads(prior.source_text) if prior.source_text else {}
    origin = calibration.summaries.origin
    for key in calibration.keys:
        section, file_name, unit = file_key(key)
        *ends, how = narrowed(calibration, key)
        low, high = (round(v / unit, 2 - _digits(v / unit)) for v in ends)
        prior_low, prior_high = next((lo / unit, hi / unit) for k, lo, hi in prior.ranges if k == key)
        old_source = table.get(section, {}).get(f"{file_name}_source", "")
        table.setdefault(section, {})[file_name] = low if low == high else [low, high]
        table[section][f"{file_name}_source"] = (
            f"calibrated from {origin} of {calibration.summaries.part} by optipose calibrate, {how}, "
            f"prior [{prior_low:.3g}, {prior_high:.3g}] "
            f"({prior.name}: {old_source})"
        )
    for key in calibration.fixed:
        section, file_name, _ = file_key(key)
        source = table.get(section, {}).get(f"{file_name}_source", "")
        table[section][f"{file_name}_source"] = (
            f"not calibrated (the emulator keeps it at its middle, {middle(*_range(prior, key)) / file_key(key)[2]:.3g}): "
            f"the prior's range ({prior.name}: {source})"
        )
    table["name"] = name
    table["description"] = f"{prior.description}; calibrated from {origin} of {calibration.summaries.part}"
    header = [
        f"# {name}: the cell '{prior.name}' calibrated by optipose calibrate on {datetime.date.today().isoformat()}",
        f"# from {origin} of {calibration.summaries.part} ({len(calibration.summaries.figures)} figures); each",
        "# calibrated range is the posterior's central 90 % (docs/calibration.md).",
    ]
    if calibration.out:
        header.append(
            f"# WARNING: the prior's ranges cannot produce {len(calibration.out)} figure(s): "
            + "; ".join(calibration.out)
        )
    text = tomli_w.dumps(table)
    text = re.sub(r"= \[\n\s+([^,\n]+),\n\s+([^,\n]+),\n\]", r"= [\1, \2]", text)  # a range on one line
    return "\n".join(header) + "\n" + text


def _range(cell, key: str) -> tuple[float, float]:
    return next((lo, hi) for k, lo, hi in cell.ranges if k == key)


def _digits(value: float) -> int:
    """The position of ``value``'s leading digit (0 for 1–9.99, -2 for 0.01–0.099), for three significant digits."""
    from math import floor, log10

    return 0 if value <= 0 else int(floor(log10(value)))


def write_cell(calibration: Calibration, path: str | Path) -> Path:
    """Write the calibrated cell file whole (:func:`optipose.files.write_text`), named after the file's stem."""
    from optipose.files import write_text

    path = Path(path)
    return write_text(path, calibrated_text(calibration, path.stem))
