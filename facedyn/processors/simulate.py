"""`usdfacedyn simulate`: simulate a corpus of takes with known truth (the papers' capture protocol).

A corpus builder: it writes a folder (corpus.json plus one take folder per take, each with
its truth beside it), the input of the trainers. A take the simulator cannot integrate is
reported, skipped and listed in corpus.json (`failed`); re-running the same command on the
same folder keeps the takes already complete and simulates only the rest
(facedyn.processors.corpus_writer.build_corpus). `synth` is its old name, kept as a deprecated alias.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from facedyn.errors import UsageError
from facedyn.processors.base import FolderOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.progress import Progress


class SimulateProcessor(Processor):
    name = "simulate"
    version = "1"
    summary = "simulate a corpus of takes with known truth (the papers' capture protocol)"
    reads = Reads("nothing")
    writes = Writes("folder", metavar="DIR", help="the corpus folder to write (an interrupted one is resumed)", resumable=True)
    parameters = (
        Parameter("scale", str, "demo", "protocol size", ("demo", "standard")),
        Parameter("rig", Path, None, "a UsdSkel blend-shape rig (default: the built-in face)", metavar="RIG"),
        Parameter("actor_seed", int, None, "make another actor from the rig's identity modes", minimum=0, maximum=2**32 - 1),
        Parameter("data", Path, None, "a ../shared/data-like folder with Live Link curves (livelink-face/*.csv) and CMU "
                  "mocap (cmu-mocap/*.bvh) for dialog takes", metavar="DIR"),
        Parameter("noise", float, 0.0, "Gaussian tracking noise on the captured points, cm", minimum=0.0, maximum=10.0, metavar="CM"),
        Parameter("seed", int, 0, "seed of the protocol's random choices", minimum=0, maximum=2**32 - 1),
        Parameter("only", str, "", "only takes whose name matches this glob pattern", metavar="PATTERN"),
        Parameter("jobs", int, os.cpu_count() or 1, "takes simulated at once", minimum=1, maximum=1024),
        Parameter("physics", str, "tissue", "soft-tissue model: tissue (facedyn's), or volumetric (a finite-element layer, "
                  "a different family for testing)", ("tissue", "volumetric")),
        Parameter("randomize_tissue", str, "none", "draw tissue parameters per take or once per corpus (the training "
                  "learns the physics family, not one model)", ("none", "take", "corpus")),
        Parameter("extra_motions", bool, False, "add dance, turn and jump takes (motions not fitted to the test mocap)"),
        Parameter("impacts", bool, False, "gaits jolt at each foot contact (6-16 Hz transients, as real walking and hopping do)"),
        Parameter("soft_hz", str, "", "draw the randomized tissue's soft frequency from this band (default: the family's "
                  "5-9 Hz), e.g. an actor's band", metavar="LOW-HIGH"),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.processors.corpus_writer import load_rig, protocol_takes

        params = request.params
        band = soft_hz_band(params["soft_hz"])
        if band is not None and params["randomize_tissue"] == "none":
            raise UsageError("--soft-hz sets the band randomized tissue is drawn from: add --randomize-tissue take (or corpus)")
        rig = load_rig(params["rig"], params["actor_seed"])
        specs = protocol_takes(rig, params["scale"], params["data"], params["only"], seed=params["seed"], noise_cm=params["noise"],
                               physics=params["physics"], extra_motions=params["extra_motions"], impacts=params["impacts"],
                               randomize_tissue=None if params["randomize_tissue"] == "none" else params["randomize_tissue"], soft_hz=band)
        description = {"takes": len(specs), "rig": str(params["rig"] or "built-in"), "points": rig.point_count}
        return Plan(description, (request, rig, specs))

    def run(self, plan: Plan, progress: Progress) -> FolderOutput:
        from facedyn.processors.corpus_writer import build_corpus

        request, rig, specs = plan.state
        params = request.params
        description = {"scale": params["scale"], "rig": str(params["rig"] or "built-in"), "actor_seed": params["actor_seed"],
                       "noise_cm": params["noise"], "seed": params["seed"], "physics": params["physics"],
                       "randomize_tissue": params["randomize_tissue"], "extra_motions": params["extra_motions"],
                       "impacts": params["impacts"], "soft_hz": params["soft_hz"] or "the family's"}
        index = build_corpus(request.output, rig, specs, progress=progress, description=description, jobs=params["jobs"],
                             other_recipes="refuse")  # a folder of another corpus is never overwritten from the command line
        return FolderOutput({"takes": len(index["takes"]), "failed": [take["name"] for take in index["failed"]],
                             "resumed": index["resumed"], "frames": index["frames"], "points": index["points"],
                             "simulated_frames_per_second": index["simulated_frames_per_second"], "jobs": params["jobs"]})


class SynthAliasProcessor(SimulateProcessor):
    """`synth`, the old name of `simulate` (it sounded like `synthesize`): the same command, with a note."""

    name = "synth"
    summary = "deprecated alias of `simulate`"

    def prepare(self, request: Request) -> Plan:
        print("usdfacedyn: `synth` is deprecated and will be removed; use `usdfacedyn simulate` (the same command)", file=sys.stderr)
        return super().prepare(request)


def soft_hz_band(text: str) -> tuple[float, float] | None:
    """--soft-hz LOW-HIGH as (low, high) Hz; None when not given."""
    if not text:
        return None
    low, sep, high = text.partition("-")
    try:
        band = (float(low), float(high)) if sep else None
    except ValueError:
        band = None
    if band is None or not (0 < band[0] <= band[1] < 1000):
        raise UsageError(f"--soft-hz {text!r}: expected a band of frequencies LOW-HIGH in Hz with 0 < LOW <= HIGH, e.g. 7.5-9")
    return band
