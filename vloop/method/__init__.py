"""The vector-loop method up to the compiled model: the paper's graph and cycle basis, the loops and their
terms (LoopSystem), the block structure, the t = 0 assembly, and the loop equations as text."""
