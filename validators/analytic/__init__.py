"""Pick the hand-derived closed form that applies to a mechanism.

Each closed-form module in ``CLOSED_FORMS`` (the eight-bar, slider-crank, four-bar,
inverted slider-crank, Whitworth, Watt II and Stephenson III six-bars, five-bar and
Jansen pair) exposes ``applies(mech)``, which inspects the structure
(bodies, pins, sliders, the driver, slider axes) rather than names, and
``solve(mech, times=None) -> Result`` (engine ``"analytic"``; the closed form
used is in ``result.meta["closed_form"]``). None of them shares code with
vloop's loop equations or solver.
"""

from __future__ import annotations

from types import ModuleType

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from . import (
    chain,
    changepoint,
    eightbar,
    fivebar,
    fourbar,
    inverted_slider_crank,
    jansen,
    sixbar_stephenson3,
    sixbar_watt2,
    slider_crank,
    whitworth,
)
from .common import LimitPositionError

CLOSED_FORMS: tuple[ModuleType, ...] = (
    eightbar,
    slider_crank,
    fourbar,
    inverted_slider_crank,
    whitworth,
    sixbar_watt2,
    sixbar_stephenson3,
    fivebar,
    jansen,
)

# Tried before CLOSED_FORMS: change-point four-bars (where fourbar's fixed branch sign would jump
# branches) continue on the velocity-continuous branch. Tried after: any other chain of dyads on cranks
# (the corpus's random attachments), solved dyad by dyad from its structure.
BEFORE: tuple[ModuleType, ...] = (changepoint,)
FALLBACK: tuple[ModuleType, ...] = (chain,)

__all__ = ["BEFORE", "CLOSED_FORMS", "FALLBACK", "LimitPositionError", "available", "closed_form_for", "solve"]


def closed_form_for(mech: Mechanism) -> ModuleType | None:
    """The closed-form module whose structure matches ``mech``, or None."""
    return next((m for m in (*BEFORE, *CLOSED_FORMS, *FALLBACK) if m.applies(mech)), None)


def available(mech: Mechanism) -> bool:
    """True if one of the closed forms applies to ``mech``."""
    return closed_form_for(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises ValueError if no closed form applies, and LimitPositionError (a
    ValueError) if the motion leaves the mechanism's assembly range.
    """
    mod = closed_form_for(mech)
    if mod is None:
        names = ", ".join(m.NAME for m in CLOSED_FORMS)
        raise ValueError(f"{mech.name}: no closed form applies (known structures: {names}; they are crank-driven)")
    return mod.solve(mech, times)
