"""How closely sampled motions pass through target points or poses, and in which order.

Used to score a search's population (the batch's samples) before any candidate is re-solved exactly.
"""

from __future__ import annotations

import numpy as np


def match(
    path: np.ndarray,
    targets: np.ndarray,
    angles: np.ndarray | None = None,
    target_angles: np.ndarray | None = None,
    arm: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each row of sampled positions ``path`` (V, n) complex and each target (N,): the distance of the
    nearest sample, that sample's index, and whether the nearest samples come in the targets' order within one
    pass over the samples (each after the one before, less than the whole sweep apart in all).

    With ``angles`` (V, n) and ``target_angles`` (N,) [rad] a pose's distance is √(|Δz|² + (arm·Δθ)²): an
    angle error weighs as much as the displacement it causes at distance ``arm`` [length]."""
    n = path.shape[1]
    d = np.abs(path[:, :, None] - targets[None, None, :])
    if angles is not None and target_angles is not None:
        dth = np.angle(np.exp(1j * (angles[:, :, None] - target_angles[None, None, :])))
        d = np.hypot(d, arm * dth)
    d = np.where(np.isfinite(d), d, np.inf)
    idx = np.argmin(d, axis=1)
    dist = np.take_along_axis(d, idx[:, None, :], axis=1)[:, 0, :]
    return dist, idx, ordered(idx, n)


def ordered(idx: np.ndarray, n: int, cyclic: bool = True) -> np.ndarray:
    """Whether the sample indices (V, N) increase target by target: strictly, and (``cyclic``: the samples are
    one period of a periodic motion) wrapping around at most once in all."""
    if idx.shape[1] < 2:
        return np.ones(len(idx), bool)
    step = np.diff(idx, axis=1)
    if not cyclic:
        return np.all(step > 0, axis=1)
    fwd = np.mod(step, n)
    return np.all(fwd > 0, axis=1) & (np.sum(fwd, axis=1) < n)
