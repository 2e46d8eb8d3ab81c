"""The accuracy the core asks of every output and the bounds a sample is judged by.

A kept sample whose velocities' error bound cond²·ε exceeds ``rtol`` is refused (a toggle); one whose
accelerations' bound cond³·ε exceeds ILL_FRACTION·rtol is flagged ill-conditioned in health. Newton stops when
its step falls below tol·(1 + |x|).
"""

from __future__ import annotations

import numpy as np

EPS = float(np.finfo(float).eps)


DEFAULT_RTOL = 1e-9  # accuracy asked of every output, relative (refusals and flags follow it: see velocity_bound)


ILL_FRACTION = 1e-3  # a kept sample whose error bound exceeds this fraction of rtol is flagged ill-conditioned


DEFAULT_TOL = 1e-12  # Newton stops when the step is below tol·(1 + |x|)


DEFAULT_MAX_ITER = 30


def error_bound(cond: np.ndarray) -> np.ndarray:
    """Relative error bound of a sample's accelerations: cond³·ε. Next to a fold the positions themselves are
    only known to cond·ε (the inputs' round-off, amplified), the velocities to cond²·ε, the accelerations to
    cond³·ε (measured on a parallelogram at its folding: the bound holds, with a margin of ~10)."""
    return cond * cond * cond * EPS


def velocity_bound(cond: np.ndarray) -> np.ndarray:
    """Relative error bound of a sample's velocities: cond²·ε (a sample beyond rtol here is refused)."""
    return cond * cond * EPS
