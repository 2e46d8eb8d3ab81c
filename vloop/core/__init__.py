"""The solve core: P/V/A of a compiled LoopSystem over samples (and over design variants) — closed-form
dyads, batched Newton, change points, exact linear rates, health."""
