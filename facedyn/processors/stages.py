"""Resumable stages of a processor that fills a folder step by step (`usdfacedyn calibrate`).

A stage's outputs are written into the folder (each atomically, by the step that makes it),
then the stage is recorded in the folder's `stages.json` with a key: a hash of everything
its result depends on (its parameters, its input files' contents, the keys of the
stages it reads). A re-run skips a stage whose record has the same key and whose outputs
are all there, and does again (outputs removed first) one that is missing, interrupted or
stale, so an interrupted run resumes where it stopped and a changed input is not missed.
"""
from __future__ import annotations

import hashlib
import json
import shutil
import time
from pathlib import Path
from typing import Callable

from facedyn.io.files import write_atomically
from facedyn.progress import Progress

RECORD = "stages.json"


def key_of(*parts) -> str:
    """A stage's key: the hash of what its result depends on (JSON-able parts; paths as text)."""
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:32]


def file_state(paths) -> list:
    """What says a set of input files changed: each one's resolved path and content id
    (facedyn.usd.runs.content_id, as staleness reads layers); a take root stands for every USD
    file of its folder (its layers)."""
    from facedyn.usd.runs import content_id

    state = []
    for path in map(Path, paths):
        files = sorted(path.parent.glob("*.usd*")) if path.suffix.lower().startswith(".usd") and path.name.startswith("take.") else [path]
        state.extend([str(file.resolve()), content_id(file)] for file in files)
    return state


class Stages:
    """The stages recorded in `folder`/stages.json, run or skipped by their keys."""

    def __init__(self, folder: Path, progress: Progress):
        self.folder, self.progress = Path(folder), progress
        path = self.folder / RECORD
        try:
            self.done = json.loads(path.read_text()) if path.is_file() else {}
        except ValueError:  # a record damaged outside facedyn: every stage runs again
            self.done = {}
        if not isinstance(self.done, dict):
            self.done = {}

    def run(self, name: str, key: str, outputs: list[Path], compute: Callable[[], dict], *, resumes: bool = False) -> dict:
        """compute()'s result (JSON-able), or the recorded one when the stage is done with this
        key and its outputs are there; `outputs` are removed before the stage runs again, unless
        the stage `resumes` from them itself (a corpus keeps its complete takes of the same recipe)."""
        entry = self.done.get(name)
        if isinstance(entry, dict) and entry.get("key") == key and all(Path(p).exists() for p in outputs):
            self.progress.start(f"{name}: done before, kept", 1)
            self.progress.finish()
            return entry["result"]
        for path in [] if resumes else map(Path, outputs):
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()
        self.progress.start(f"{name}: running", 1)
        started = time.perf_counter()
        result = compute()
        self.done[name] = {"key": key, "seconds": round(time.perf_counter() - started, 1), "result": result}
        self._save()
        return result

    def seconds(self) -> dict[str, float]:
        """{stage: seconds it took when it ran}."""
        return {name: entry["seconds"] for name, entry in self.done.items() if isinstance(entry, dict) and "seconds" in entry}

    def _save(self) -> None:
        text = json.dumps(self.done, indent=2, sort_keys=True).encode() + b"\n"
        write_atomically(self.folder / RECORD, lambda out: out.write(text))
