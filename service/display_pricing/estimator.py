"""Ratio estimators over the sampled blocks: a frame's error sum, activity counters and comparator
histogram from the sample's display-resolution values and the auxiliary frames' totals."""

from __future__ import annotations

import math

import numpy as np
from sim_core.render import COUNTER_NAMES

from service.display_pricing.sampling import CameraDesign


def _ratio(y: np.ndarray, x_sample: np.ndarray, x_total: float, pi: np.ndarray) -> tuple[float, float]:
    """Ratio estimate of a total (and its approximate standard error) from sampled values ``y``, their
    auxiliary values and the auxiliary total; Horvitz-Thompson where the auxiliary carries nothing."""
    ht_y = float(np.sum(y / pi))
    ht_x = float(np.sum(x_sample / pi))
    if x_total > 0 and ht_x > 0:
        rate = ht_y / ht_x
        est = x_total * rate
        resid = y - rate * x_sample
    else:
        est, resid = ht_y, y
    loose = pi < 1.0
    k = int(loose.sum())
    if k < 2:
        return est, 0.0
    t = k * resid[loose] / pi[loose]
    se = math.sqrt(float(np.sum((t - t.mean()) ** 2)) / (k * (k - 1)))
    return est, se


def estimate(d: CameraDesign, sample_err: np.ndarray | None, sample_cnt: np.ndarray, sample_hist: np.ndarray,
              sample_owner: np.ndarray, aux: tuple, render_size: tuple[int, int]
              ) -> tuple[float, float, dict[str, int], np.ndarray, float]:
    """(error, its standard error, counters, histogram, relative standard error of rays_total)."""
    blocks = d.sampled
    pi = d.pi[blocks]
    x_err, x_cnt, x_hist = aux[0], aux[1], aux[2]
    if sample_err is None:  # the reference itself
        error, se_err = 0.0, 0.0
    else:
        total, se = _ratio(sample_err, x_err[blocks], float(x_err.sum()), pi)
        error = min(max(total / d.interior, 0.0), 1.0) if d.interior else 0.0
        se_err = se / d.interior if d.interior else 0.0
    y_cnt = np.zeros((len(blocks), sample_cnt.shape[1]))
    pos = {int(b): i for i, b in enumerate(blocks)}
    np.add.at(y_cnt, [pos[int(b)] for b in sample_owner], sample_cnt.astype(np.float64))
    y_hist = np.zeros((len(blocks), 25))
    np.add.at(y_hist, [pos[int(b)] for b in sample_owner], sample_hist.astype(np.float64))
    counters: dict[str, int] = {}
    se_rays = 0.0
    for i, name in enumerate(COUNTER_NAMES):
        est, se = _ratio(y_cnt[:, i], x_cnt[blocks, i], float(x_cnt[:, i].sum()), pi)
        counters[name] = max(0, round(est))
        if name == "rays_total" and est > 0:
            se_rays = se / est
    w, h = render_size
    counters["pixels"] = w * h
    counters["framebuffer_bytes"] = 4 * w * h
    hist = np.zeros(25)
    for i in range(25):
        hist[i] = max(0.0, _ratio(y_hist[:, i], x_hist[blocks, i], float(x_hist[:, i].sum()), pi)[0])
    hist_total = hist.sum()
    if hist_total > 0:  # the histogram counts the closest-hit comparisons
        hist *= counters["closest_hit_comparisons"] / hist_total
    return error, se_err, counters, np.round(hist).astype(np.int64), se_rays
