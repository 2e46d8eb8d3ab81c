"""Design from motion: dimensional synthesis of linkages, every answer re-solved and checked by vloop.

    import vloop.synthesis as syn
    gen = syn.function("log10(x)", x_range=(1, 2), input_range=(0.5, 2.0), output_range=(4.0, 5.5))
    guide = syn.motion([[0, 0, 0], [1, 0.5, 0.3], [2, 0.4, 0.8]], dyads=[{"fixed": (0, -1)}, {"fixed": (2, -1)}])
    trace = syn.path([[0, 1], [1, 2], [2, 1.5], [3, 0], [1.5, -0.5]], seed=1)
    trace.table()                    # ranked candidates (pandas), solutions first
    trace.best.mechanism             # a Mechanism that runs as it is: vloop.solve(trace.best.mechanism)

A consumer of the solver like the design studies: the methods propose linkages (:mod:`.function`: Freudenstein,
the slider-crank; :mod:`.motion`: the dyad form, Burmester; :mod:`.path`: differential evolution over batched
solves, then least squares), and every candidate is re-solved over its whole motion (:mod:`.defects`: branch,
circuit and order defects, full rotation, transmission angle, the error at each precision position). The
synthesis file and ``vloop synth`` are in :mod:`.spec` and :mod:`.report`.
"""

from __future__ import annotations

from .candidates import Candidate, Candidates, Task
from .defects import Requirements
from .function import function
from .motion import motion
from .path import path
from .report import write
from .spec import SynthSpec, load, run

__all__ = [
    "Candidate",
    "Candidates",
    "Requirements",
    "SynthSpec",
    "Task",
    "function",
    "load",
    "motion",
    "path",
    "run",
    "write",
]
