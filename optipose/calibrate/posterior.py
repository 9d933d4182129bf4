"""The posterior of a cell's ranged magnitudes given a hand layout's measured figures (docs/calibration.md).

Likelihood-free in the sense of ABC, exact for its kernel: the simulator is the surrogate's emulator
(:mod:`optipose.calibrate.emulator`), corrected to ICP by a per-figure log-ratio (:class:`Correction`, fitted on a
few ICP evaluations at prior draws), and its kernel is the Gaussian noise of a figure's log — the finite scans'
(:meth:`optipose.calibrate.summaries.Summaries.noise`) plus the correction's spread (how far one ICP cell instance
lands from the emulator's prediction). With that kernel the ABC posterior is the prior times a Gaussian likelihood,
so an importance sampler draws it:

1. ``draws`` settings from the prior (each range's draw in its quantile u ∈ [0, 1]: log-uniform, or uniform from 0),
   weighted by the likelihood;
2. if their effective sample size is below :data:`_ESS`, ``draws`` more from a defensive mixture (half the prior,
   half uniform on the box that holds the first round's weighted 0.5–99.5 % of each u, widened by a tenth), weighted
   by likelihood × prior / mixture; the posterior is the second round's.

Whether the ranges can produce the figures at all (:func:`misfit`): the best draw's χ² is beyond the 99.9 % quantile
of χ² with as many degrees of freedom as figures ("the model is missing a source"); the figures named are those
outside what every prior draw predicts by more than three of their noise's σ, else those the best draw misses by
more than three σ. One figure far off among many that fit (one instance's part as made can put a roll figure far
below the instances' average) is not a missing source.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from optipose.cell.ranges import quantile

__all__ = ["Correction", "Posterior", "fit_correction", "sample", "misfit", "prior_draws", "weighted_quantiles"]

_ESS = 400  # effective samples below which a second round is drawn
_OUT_SIGMA = 3.0  # a figure beyond every prior prediction by more than this many σ of its noise is out
_SHRINK = 3.0  # pseudo-observations of the pooled spread in each figure's correction spread
_DEFAULT_SPREAD = 0.35  # log, the correction's σ without ICP evaluations (about the surrogate's ranking error)


@dataclass(frozen=True)
class Correction:
    """ICP / emulator per figure: ``log_ratio`` (figures,) the mean log-ratio, ``cov`` (figures, figures) its
    spread's covariance (one ICP instance about the corrected prediction, plus the mean's own uncertainty),
    ``seeds`` the ICP evaluations' seeds (cell instances) and ``seconds`` their wall time."""

    log_ratio: np.ndarray
    cov: np.ndarray
    seeds: tuple[int, ...]
    seconds: float


def fit_correction(emulated: np.ndarray, icp: np.ndarray, related: list, seeds, seconds) -> Correction:
    """The :class:`Correction` from the logs of the emulated and the ICP figures at the same magnitude settings,
    (m, figures) each. ``related``: lists of figure index pairs whose residuals share one correlation, each list's
    pooled over its pairs (the median and p75 of one subset and axis; the figures of one axis on other subsets, whose
    errors one robot path or one part drives together): without it, forty figures of one axis would count as forty
    independent measurements of what is one. Without evaluations (m = 0): no ratio, a spread of
    :data:`_DEFAULT_SPREAD`, the same correlations at 0.5."""
    n = emulated.shape[1]
    r = icp - emulated
    if len(r):  # a figure ICP left undefined at an instance (an axis unobservable there) counts as the others' mean
        r = np.where(np.isfinite(r), r, np.nanmean(np.where(np.isfinite(r), r, np.nan), axis=0, keepdims=True))
        r = np.where(np.isfinite(r), r, 0.0)
    m = len(r)
    mean = r.mean(axis=0) if m else np.zeros(n)
    if m < 2:
        var, rhos = np.full(n, _DEFAULT_SPREAD**2), [0.5] * len(related)
    else:
        dev = r - mean
        own = (dev**2).sum(axis=0) / (m - 1)
        pooled = float(own.mean())
        var = ((m - 1) * own + _SHRINK * pooled) / (m - 1 + _SHRINK)  # each figure's, shrunk to the pooled one
        rhos = [_pooled_correlation(dev, pairs) for pairs in related]
    if m:
        var = var * (1 + 1 / m)  # a new instance about a mean of m
    cov = np.diag(var)
    for pairs, rho in zip(related, rhos):
        for i, j in pairs:
            cov[i, j] = cov[j, i] = rho * np.sqrt(var[i] * var[j])
    w, V = np.linalg.eigh(cov)  # pooled correlations need not make a covariance: its nearest one
    cov = (V * np.maximum(w, 1e-3 * w.max())) @ V.T
    return Correction(mean, cov, tuple(int(s) for s in seeds), float(seconds))


def _pooled_correlation(dev: np.ndarray, pairs) -> float:
    num = sum(float(dev[:, i] @ dev[:, j]) for i, j in pairs)
    den = sum(float(np.sqrt((dev[:, i] @ dev[:, i]) * (dev[:, j] @ dev[:, j]))) for i, j in pairs)
    return float(np.clip(num / den, 0.0, 0.95)) if den > 0 else 0.0


@dataclass(frozen=True)
class Posterior:
    """Weighted magnitude settings: ``u`` (n, keys) their quantiles in the prior ranges, ``values`` (n, keys) SI,
    ``weights`` (n,) summing to 1, ``ess`` the effective sample size, ``rounds`` 1 or 2, ``best`` (figures,) the
    standardised residuals of the best-fitting setting."""

    keys: tuple[str, ...]
    u: np.ndarray
    values: np.ndarray
    weights: np.ndarray
    ess: float
    rounds: int
    best: np.ndarray

    def quantile_u(self, j: int, q: float) -> float:
        """The weighted ``q`` quantile of key ``j``'s place in its prior's draw (0: its low end, 1: its high end)."""
        return weighted_quantiles(self.u[:, j], self.weights, [q])[0]

    def interval(self, key: str, low: float = 0.05, high: float = 0.95) -> tuple[float, float]:
        """The weighted ``low`` and ``high`` quantiles of ``key``'s magnitude (SI)."""
        j = self.keys.index(key)
        return tuple(weighted_quantiles(self.values[:, j], self.weights, [low, high]))


def prior_draws(ranges: list[tuple[str, float, float]], u: np.ndarray) -> np.ndarray:
    """(n, keys) SI magnitudes at quantiles ``u`` (n, keys) of ``ranges`` (``(field, low, high)`` rows)."""
    return np.column_stack(
        [np.vectorize(lambda q, lo=lo, hi=hi: quantile(lo, hi, q))(u[:, j]) for j, (_, lo, hi) in enumerate(ranges)]
    )


def sample(simulate, ranges, observed: np.ndarray, cov: np.ndarray, draws: int, seed: int) -> tuple:
    """The :class:`Posterior` of ``ranges`` (``(field, low, high)`` rows) given the observed logs (figures,) with
    noise covariance ``cov``; ``simulate(values)`` returns the predicted logs (n, figures) at settings (n, keys) SI.
    Returns the posterior and the first round's predictions (draws, figures) for :func:`misfit`."""
    rng = np.random.default_rng(seed)
    d = len(ranges)
    precision = np.linalg.inv(cov)
    u = rng.random((draws, d))
    predicted = simulate(prior_draws(ranges, u))
    logw = _loglik(predicted, observed, precision)
    first = predicted
    rounds = 1
    if _ess(logw) < _ESS:
        w = _normalised(logw)
        lo = np.array([weighted_quantiles(u[:, j], w, [0.005])[0] for j in range(d)])
        hi = np.array([weighted_quantiles(u[:, j], w, [0.995])[0] for j in range(d)])
        pad = 0.1 * np.maximum(hi - lo, 0.02)
        lo, hi = np.clip(lo - pad, 0, 1), np.clip(hi + pad, 0, 1)
        from_box = rng.random(draws) < 0.5
        u = np.where(from_box[:, None], lo + rng.random((draws, d)) * (hi - lo), rng.random((draws, d)))
        inside = np.all((u >= lo) & (u <= hi), axis=1)
        mixture = 0.5 + 0.5 * inside / np.prod(hi - lo)
        predicted = simulate(prior_draws(ranges, u))
        logw = _loglik(predicted, observed, precision) - np.log(mixture)
        rounds = 2
    weights = _normalised(logw)
    best = int(np.argmax(_loglik(predicted, observed, precision)))
    residual = (observed - predicted[best]) / np.sqrt(np.diag(cov))
    keys = tuple(f for f, _, _ in ranges)
    posterior = Posterior(keys, u, prior_draws(ranges, u), weights, _ess(logw), rounds, residual)
    return posterior, first


def misfit(first: np.ndarray, observed: np.ndarray, cov: np.ndarray, posterior: Posterior) -> list[int]:
    """The figures (indices) the ranges cannot produce (module doc); empty when they can."""
    if float(posterior.best @ posterior.best) <= chi2.ppf(0.999, len(observed)):
        return []  # one figure far off among many that fit is one instance's draw, not a missing source
    sd = np.sqrt(np.diag(cov))
    out = np.flatnonzero(
        (observed < first.min(axis=0) - _OUT_SIGMA * sd) | (observed > first.max(axis=0) + _OUT_SIGMA * sd)
    )
    if len(out):
        return [int(i) for i in out]
    worst = np.argsort(-np.abs(posterior.best))
    return [int(i) for i in worst if abs(posterior.best[i]) > _OUT_SIGMA] or [int(worst[0])]


def _loglik(predicted: np.ndarray, observed: np.ndarray, precision: np.ndarray) -> np.ndarray:
    r = observed[None] - predicted
    return -0.5 * np.einsum("ni,ij,nj->n", r, precision, r)


def _normalised(logw: np.ndarray) -> np.ndarray:
    w = np.exp(logw - logw.max())
    return w / w.sum()


def _ess(logw: np.ndarray) -> float:
    w = _normalised(logw)
    return float(1.0 / (w**2).sum())


def weighted_quantiles(x: np.ndarray, w: np.ndarray, qs) -> list[float]:
    order = np.argsort(x)
    c = np.cumsum(w[order])
    c = (c - 0.5 * w[order]) / c[-1]
    return [float(np.interp(q, c, x[order])) for q in qs]
