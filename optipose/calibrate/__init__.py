"""Calibration: a cell's ranges narrowed to what a hand layout's measured Table 1 shows (docs/calibration.md).

``emulator`` (the surrogate's Table 1 for any magnitudes), ``summaries`` (the measured figures: a published table or
an evaluation of scans, and their noise), ``posterior`` (the importance sampler over the ranges, the ICP correction,
the check that the ranges can produce the figures), ``cellfile`` (the calibrated cell file), ``calibration`` (the
whole run).
"""
