"""`simulate` on a Dask cluster: one task per take, the same corpus whatever the worker count.

Each task simulates one take (seeded by its TakeSpec, so no result depends on which worker
ran it or when) and writes it with facedyn.usd.corpus.write_simulated_take; the index lists
the takes in the order of the specs. The rig goes to the workers once.
"""
from __future__ import annotations

import time
import uuid
from pathlib import Path

from facedyn.batch.cluster import RETRIES
from facedyn.progress import Progress
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.rig import FaceRig
from facedyn.sim.tissue import TissueParams


def simulate_and_write(folder: Path, rig: FaceRig, spec: TakeSpec, tissue: TissueParams | None) -> tuple[dict, float]:
    """(the take's corpus index entry, seconds spent writing): the task of one take."""
    from facedyn.usd.corpus import write_simulated_take

    take = simulate_take(rig, spec, tissue)
    started = time.perf_counter()
    entry = write_simulated_take(folder, take, rig)
    return entry, time.perf_counter() - started


def build_corpus_on(client, output: Path, rig: FaceRig, specs: list[TakeSpec], tissue: TissueParams | None = None,
                    progress: Progress | None = None, description: dict | None = None) -> dict:
    """Simulate and write every take of `specs` on the cluster; return the corpus index (facedyn.usd.corpus's)."""
    from distributed import as_completed

    from facedyn.usd.corpus import corpus_folder, write_corpus_index

    progress = progress or Progress.silent()
    output = corpus_folder(output).absolute()
    started = time.perf_counter()
    shared_rig = client.scatter(rig, broadcast=True)
    batch = uuid.uuid4().hex[:8]
    futures = [client.submit(simulate_and_write, output / spec.name, shared_rig, spec, tissue, key=f"simulate-{spec.name}-{batch}",
                             pure=False, retries=RETRIES) for spec in specs]
    progress.start(f"simulate {len(specs)} takes", len(specs))
    for _ in as_completed(futures):
        progress.advance()
    progress.finish()
    results = client.gather(futures)
    workers = len(client.scheduler_info()["workers"])
    return write_corpus_index(output, rig, tissue, [entry for entry, _ in results], description, workers,
                              sum(seconds for _, seconds in results), time.perf_counter() - started)
