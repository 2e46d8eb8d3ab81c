"""Files and outputs: the mechanism file's schema and reader, safe output sets, streamed writers, memory
budgets and the progress bar. Nothing here knows the method; everything above reads and writes through it."""
