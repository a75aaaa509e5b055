"""`simulate` on a Dask cluster: one task per take, the same corpus whatever the worker count.

Each task simulates one take (seeded by its TakeSpec, so no result depends on which worker
ran it or when) and writes it atomically with its recipe (facedyn.usd.corpus_files,
facedyn.processors.corpus_writer), so a corpus resumes and skips failing takes as `simulate` does; the index lists the takes in the order
of the specs. The rig goes to the workers once.
"""
from __future__ import annotations

import time
import uuid
from pathlib import Path

from facedyn.batch.cluster import RETRIES
from facedyn.errors import FacedynError
from facedyn.progress import Progress
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.rig import FaceRig
from facedyn.sim.tissue import TissueParams


def simulate_and_write(output: Path, rig: FaceRig, spec: TakeSpec, tissue: TissueParams | None,
                       recipe: dict) -> tuple[dict | None, str | None, float]:
    """The task of one take: (its corpus index entry, None, seconds spent writing), or (None, the error, 0)
    when the take cannot be simulated (a FacedynError: skipped and recorded, the others go on)."""
    from facedyn.usd.corpus_files import write_take_atomically

    try:
        take = simulate_take(rig, spec, tissue)
    except FacedynError as exc:
        return None, str(exc).removeprefix(f"take {spec.name}: "), 0.0
    started = time.perf_counter()
    entry = write_take_atomically(output, take, rig, recipe)
    return entry, None, time.perf_counter() - started


def build_corpus_on(client, output: Path, rig: FaceRig, specs: list[TakeSpec], tissue: TissueParams | None = None,
                    progress: Progress | None = None, description: dict | None = None) -> dict:
    """Simulate and write every take of `specs` on the cluster; return the corpus index (build_corpus's:
    complete takes of an earlier run kept, failed takes skipped and recorded)."""
    from distributed import as_completed

    from facedyn.processors.corpus_writer import ResumedCorpus
    from facedyn.usd.corpus_files import corpus_folder

    progress = progress or Progress.silent()
    output = corpus_folder(output).absolute()
    started = time.perf_counter()
    corpus = ResumedCorpus(output, rig, specs, tissue)
    todo = corpus.missing()
    shared_rig = client.scatter(rig, broadcast=True)
    batch = uuid.uuid4().hex[:8]
    futures = [client.submit(simulate_and_write, output, shared_rig, spec, tissue, corpus.recipes[spec.name],
                             key=f"simulate-{spec.name}-{batch}", pure=False, retries=RETRIES) for spec in todo]
    progress.start(f"simulate {len(specs)} takes", len(specs))
    progress.advance(corpus.resumed)
    for _ in as_completed(futures):
        progress.advance()
    progress.finish()
    for spec, (entry, error, seconds) in zip(todo, client.gather(futures)):
        if error is None:
            corpus.done[spec.name] = entry
            corpus.written += seconds
        else:
            corpus.errors[spec.name] = error
            progress.note(f"take {spec.name} skipped: {error}")
    workers = len(client.scheduler_info()["workers"])
    return corpus.write_index(description, workers, time.perf_counter() - started)
