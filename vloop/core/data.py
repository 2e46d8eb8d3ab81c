"""The solver's data: where every rotating link and slider is, how fast it moves, at every row.

Pinocchio's Model/Data split: the compiled :class:`~vloop.method.loops.LoopSystem` is the model (immutable), a
:class:`State` is the data every algorithm of the core fills. Rows are samples; several variants of one
system solved together stack their samples, variant by variant (rows v·n … v·n + n − 1 are variant v's n
samples; :meth:`State.per_variant`). Columns:

* ``e[:, a]`` = e^{jθ_a} (a unit complex number) and ``theta[:, a]`` = θ_a [rad] (unwrapped: continuous over the
  samples, whole turns counted) of rotating link a (the LoopSystem's angle variable a), ``omega[:, a]`` its
  ω [rad/s] and ``alpha[:, a]`` its α [rad/s²], CCW positive;
* ``s[:, i]``, ``s_dot[:, i]``, ``s_ddot[:, i]``: slider i's displacement along its axis [length], its rate and
  its acceleration.

Every array but ``theta`` has a last padding column (e = 1, every other array 0) that stands for "fixed": a
vector term that no link turns or no slider lengthens indexes it with −1. Term vectors are
z = (r + s)·e^{jδ}·e, so ż = ṡ·e^{jδ}e + jω·z and z̈ = s̈·e^{jδ}e + 2jṡω·e^{jδ}e + (jα − ω²)·z.
"""

from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


class State:
    """The state arrays of ``variants`` × ``samples`` rows (see the module notes for the columns).

    Column-major: every column (an angle's e^{jθ}, a slider's s, ...) is contiguous, as the dyads and the sums
    read and write them one at a time; row-major, each pass over a column read every row's cache line (with it,
    the eight-bar took 1.1× the time at 4,800 samples and 1.3× at 48,000, the Jansen pair 1.2× and 1.7× with
    its 13 columns split into chunks of 12,000 to stay in cache)."""

    FIELDS = ("e", "theta", "omega", "alpha", "s", "s_dot", "s_ddot")
    POSITIONS = ("e", "theta", "s")  # what a row's configuration is (rates follow from it)

    def __init__(self, samples: int, n_angles: int, n_sliders: int, variants: int = 1) -> None:
        n = samples * variants
        self.samples, self.variants = samples, variants
        self.e = np.ones((n_angles + 1, n), complex).T
        self.theta = np.zeros((n_angles, n)).T
        self.omega = np.zeros((n_angles + 1, n)).T
        self.alpha = np.zeros((n_angles + 1, n)).T
        self.s = np.zeros((n_sliders + 1, n)).T
        self.s_dot = np.zeros((n_sliders + 1, n)).T
        self.s_ddot = np.zeros((n_sliders + 1, n)).T

    def per_variant(self, name: str) -> np.ndarray:
        """Array ``name`` (one of FIELDS) as (variants, samples, columns): a view, not a copy."""
        a = getattr(self, name)
        return a.reshape(self.variants, self.samples, a.shape[1])

    def rows(self, k: slice) -> State:
        """Rows ``k`` as a state of their own (views: writing to it writes to this state)."""
        out = State.__new__(State)
        for name in self.FIELDS:
            setattr(out, name, getattr(self, name)[k])
        out.samples, out.variants = len(out.e), 1
        return out

    def copy_positions(self, k: slice) -> State:
        """A copy of rows ``k``'s positions (e, θ, s: rates are recomputed where a state is carried on)."""
        out = State.__new__(State)
        for name in self.POSITIONS:
            setattr(out, name, getattr(self, name)[k].copy())
        out.samples, out.variants = len(out.e), 1
        return out

    def term_vectors(
        self, k: slice | np.ndarray, ang: np.ndarray, sl: np.ndarray, r: np.ndarray, cd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Term vectors z = (r + s)·e^{j(θ + δ)} and their unit directions over rows ``k`` (terms given by their
        angle column ``ang``, slider column ``sl``, length r and e^{jδ} = cd)."""
        e = cd * self.e[k][:, ang]
        return (r + self.s[k][:, sl]) * e, e

    def set_angle(self, k: slice, a: int, cis: np.ndarray) -> None:
        """Store e^{jθ} and the unwrapped θ = φ + 2π·n for rows ``k`` (row k.start keeps its turn count; several
        variants: ``k`` all rows, each variant's first row keeps its own).

        φ is the principal angle of ``cis`` (e^{jθ} up to its length), n the whole turns counted by continuity from
        the first row: the stored θ is then exactly φ + 2πn whatever the sampling before it, so a run that starts
        late gives the same numbers as one from t = 0.
        """
        cis = cis / np.abs(cis)
        self.e[k, a] = cis
        phi = np.arctan2(cis.imag, cis.real)
        if self.variants > 1:
            self.theta[k, a] = self._unwrap_variants(phi, a)
            return
        start = self.theta[k.start or 0, a]
        turns = np.empty(len(phi))  # whole turns between each row's principal angle and the one before
        turns[:1] = phi[:1] - start
        np.subtract(phi[1:], phi[:-1], out=turns[1:])
        turns *= 1.0 / TWO_PI
        np.rint(turns, out=turns)
        jumps = np.flatnonzero(turns != 0)  # few: where φ wraps past ±π
        th = phi
        if len(jumps):  # θ = φ + 2π·n, n the turns counted so far (piecewise constant between jumps)
            n = np.zeros(len(phi))
            if len(jumps) <= 8:
                for j in jumps.tolist():
                    n[j:] -= turns[j]
            else:
                n[jumps[0] :] = np.repeat(-np.cumsum(turns[jumps]), np.diff(np.append(jumps, len(phi))))
            th = phi + TWO_PI * n
        self.theta[k, a] = th

    def _unwrap_variants(self, phi: np.ndarray, a: int) -> np.ndarray:
        """θ = φ + 2π·n on every row of every variant, the turns n counted from each variant's first row (whose θ
        is the reference: the turns before it kept), as :meth:`set_angle` counts them for one."""
        V, n = self.variants, self.samples
        phi = phi.reshape(V, n)
        turns = np.empty((V, n))
        turns[:, 0] = phi[:, 0] - self.per_variant("theta")[:, 0, a]
        np.subtract(phi[:, 1:], phi[:, :-1], out=turns[:, 1:])
        turns *= 1.0 / TWO_PI
        np.rint(turns, out=turns)
        th = phi + TWO_PI * -np.cumsum(turns, axis=1)
        return np.where(np.any(turns != 0, axis=1)[:, None], th, phi).reshape(-1)


class Probe(State):
    """A state whose rows are independent instants (probes at scattered times, in any order): e^{jθ} only, no
    unwrapped θ (turns are counted along a run, not between unrelated rows)."""

    def set_angle(self, k: slice, a: int, cis: np.ndarray) -> None:
        self.e[k, a] = cis / np.abs(cis)
