"""Design studies: a study file (grids and tolerances over a mechanism's dimensions), many variants solved
together, sensitivities, tables and pictures."""
