"""The corpus writer: simulate a protocol's takes and write them as a corpus folder (facedyn.usd.corpus_files), resuming.

The one place outside the simulator where takes are simulated for a corpus: `simulate`,
`calibrate`'s first stage, the demo and `batch`'s Dask corpus (facedyn.batch.cluster_corpus) build
theirs here, so the corpus's files (facedyn.usd.corpus_files) and everything that reads them stay
free of the simulator.
"""
from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path

from facedyn.errors import FacedynError
from facedyn.progress import Progress
from facedyn.rig import FaceRig
from facedyn.sim.corpus import TakeSpec, check_data_folder, protocol, simulate_each, takes_matching
from facedyn.sim.tissue import TissueParams
from facedyn.usd.corpus_files import (complete_take, corpus_folder, rig_fingerprint, sweep_partial_takes, take_recipe, write_corpus_index,
                                write_take_atomically)


def load_rig(path: Path | None, actor_seed: int | None = None):
    """The built-in face or a USD blend-shape rig, optionally turned into another actor."""
    if path is None:
        from facedyn.sim.default_face import default_face

        rig = default_face()
    else:
        from facedyn.usd.blendshape_rig import read_blendshape_rig

        rig = read_blendshape_rig(path)
    return rig if actor_seed is None else rig.make_actor(seed=actor_seed)


def protocol_takes(rig: FaceRig, scale: str, data: Path | None, only: str = "", only_flag: str = "--only", **options) -> list[TakeSpec]:
    """The protocol's takes (facedyn.sim.corpus.protocol with `options`) named by the glob `only`; a
    UsageError, naming `only_flag` or --data, for a data folder that lacks the protocol's files or a
    pattern no take matches."""
    check_data_folder(data, scale)
    return takes_matching(protocol(rig, scale, data, **options), only, scale, only_flag)


def build_corpus(
    output: Path,
    rig: FaceRig,
    specs: list[TakeSpec],
    tissue: TissueParams | None = None,
    progress: Progress | None = None,
    description: dict | None = None,
    jobs: int = 1,
    *,
    other_recipes: str = "redo",
) -> dict:
    """Simulate (`jobs` takes at a time) and write every take of `specs`; return the corpus index.

    Takes already complete in `output` with the same recipe are kept (an interrupted corpus
    resumes); a complete take of another recipe is simulated again (`other_recipes`
    'redo') or refused ('refuse': a FacedynError naming what differs). A take the
    simulator cannot integrate is reported, skipped and listed under `failed`: the others
    go on, and the corpus is written when at least one take is.
    """
    progress = progress or Progress.silent()
    output = corpus_folder(output)
    started = time.perf_counter()
    corpus = ResumedCorpus(output, rig, specs, tissue, other_recipes)
    progress.start(f"simulate {len(specs)} takes", len(specs))
    if corpus.resumed:
        progress.note(f"{output}: {corpus.resumed} of {len(specs)} takes already complete, kept")
        progress.advance(corpus.resumed)
    for spec, take, error in simulate_each(rig, corpus.missing(), tissue, jobs):
        if error is not None:
            corpus.errors[spec.name] = error
            progress.note(f"take {spec.name} skipped: {error}")
        else:
            t0 = time.perf_counter()
            corpus.done[spec.name] = write_take_atomically(output, take, rig, corpus.recipes[spec.name])
            corpus.written += time.perf_counter() - t0
        progress.advance()
    progress.finish()
    return corpus.write_index(description, jobs, time.perf_counter() - started)


class ResumedCorpus:
    """A corpus folder's takes for `specs`: their recipes, the ones complete (kept from an earlier run, or
    written now: `done`, name -> corpus entry) and the ones that failed (`errors`, name -> message)."""

    def __init__(self, output: Path, rig: FaceRig, specs: list[TakeSpec], tissue: TissueParams | None, other_recipes: str = "redo"):
        if other_recipes not in ("redo", "refuse"):
            raise ValueError(f"other_recipes must be 'redo' or 'refuse', got {other_recipes!r}")
        self.output, self.rig, self.specs, self.tissue = output, rig, specs, tissue
        rig_hash = rig_fingerprint(rig)
        self.recipes = {spec.name: take_recipe(spec, rig_hash, tissue) for spec in specs}
        sweep_partial_takes(output)
        refuse = other_recipes == "refuse"
        self.done = {spec.name: entry for spec in specs
                     if (entry := complete_take(output / spec.name, self.recipes[spec.name], refuse)) is not None}
        self.resumed = len(self.done)
        self.errors: dict[str, str] = {}
        self.written = 0.0  # seconds spent writing takes

    def missing(self) -> list[TakeSpec]:
        return [spec for spec in self.specs if spec.name not in self.done]

    def write_index(self, description: dict | None, jobs: int, total: float) -> dict:
        """corpus.json for the takes in the specs' order; a FacedynError when none of them could be simulated."""
        failed = [{"name": spec.name, "error": self.errors[spec.name]} for spec in self.specs if spec.name in self.errors]
        if self.specs and not self.done:
            raise FacedynError(f"{self.output}: no take could be simulated; {failed[0]['name']}: {failed[0]['error']}")
        takes = [self.done[spec.name] for spec in self.specs if spec.name in self.done]
        return write_corpus_index(self.output, self.rig, asdict(self.tissue or TissueParams()), takes, description, jobs, self.written, total,
                                  failed=failed, resumed=self.resumed)
