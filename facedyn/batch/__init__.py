"""Batches of takes on a Dask cluster: `usdfacedyn batch` and `synth` with one task per take.

A batch runs facedyn's own commands (import, stabilize, remove, synthesize, preview) for
many captures, one Dask task per (take, step) chained along the steps, on an embedded local
cluster or an existing one (facedyn.batch.cluster). Each step is skipped when its output
and provenance say it is already done (facedyn.batch.state), so a batch is resumable; a
failing take is reported and the others go on. facedyn.batch.corpus builds a simulated
corpus with one task per take. Nothing here imports pxr: the steps go through the CLI.
"""
