"""The solve core: P/V/A of a compiled LoopSystem (the model) into a State (the data) over samples, and over
design variants stacked in the same state — closed-form dyads, Newton blocks, change points, exact linear
rates, health. Modules from the top of their import order: ``batch`` (many variants), ``solver`` (a run over
time), ``results`` and ``grid``, ``blocks`` (the blocks in order), ``newton`` and ``changepoints``, ``dyads`` and
``context``, ``plans``, ``sums``, ``data`` (the State) and ``linalg``, ``accuracy`` and ``variants``."""
