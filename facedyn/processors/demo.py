"""`usdfacedyn demo`: the whole pipeline on the built-in face, measured against truth.

1. simulate a small corpus (the papers' protocol at demo scale, with a procedural talking
   face under every motion: facedyn.sim.speech) with known truth, into a temporary folder
   unless --keep-corpus true keeps it in DIR/corpus for the next run;
2. simulate a new performance (a held smile while walking, with tracking noise);
3. make the actor from the rig (`usdfacedyn actor`: the skull frame the corpus and the
   models share) and stabilize the take into it (mode pursuit with --actor, and the
   three-point baseline for comparison);
4. train the removal network F the recommended way (the corpus's true dynamics, skull
   landmark accelerations over t-30..t+10, each skin sample's rest position) and remove the
   performance's dynamics;
5. train the synthesis network H on that F's quasistatic output and re-synthesize the
   dynamics under the take's own motion and under a new motion (hopping), which is also
   simulated for the truth;
6. write the layered take, a contact sheet and EXR uv offset maps, and print a summary.

Every step goes through the same processors as the CLI (facedyn.processors.runner), so the
take's root layer ends up with the stack: synthesized.hop -> quasistatic -> stabilized ->
capture. The demo is itself a processor (it writes a folder), registered as `demo`.
"""
from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import facedyn
from facedyn.performance import CAPTURED, TAKE_ROOT_FILE, role
from facedyn.processors.base import FolderOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.progress import Progress

SCALES = {
    # corpus scale, performance length (s), F epochs, subsample and batch size, H epochs
    "demo": {"corpus": "demo", "seconds": 3.0, "f_epochs": 8, "f_subsample": 0.4, "f_batch": 2000, "h_epochs": 20},
    "standard": {"corpus": "standard", "seconds": 6.0, "f_epochs": 20, "f_subsample": 0.25, "f_batch": 2000, "h_epochs": 30},
}


NOISE_CM = 0.01  # tracking noise of every simulated take, cm per coordinate (a good marker-less capture)

# What each row of the summary measures (printed under the table).
MEANINGS = {
    "removed offsets vs true offsets": "what F removed against the simulator's true dynamics: the removal figure (0% perfect, 100% = removing nothing)",
    "removed vs true quasistatic": "the quasistatic take against the true quasistatic skin; includes the capture's tracking noise, which removal leaves",
    "captured vs true quasistatic (do nothing)": "the stabilized capture itself against the true quasistatic skin: the score of not removing (about 100%)",
    "re-synthesized vs captured (own motion)": "H re-synthesizing the removed dynamics under the take's own skull motion, against the capture",
    "synthesized vs simulated truth (hop)": "H's dynamics under a new motion (hopping) against the simulator's dynamics for that motion: the synthesis figure",
}
PATH = ("recommended path: actor from the rig (the skull frame), take stabilized into it (solved skull, not the true one); "
        "F trained on the corpus's true dynamics (held expressions and a procedural talking face) with skull landmark "
        "accelerations and each skin sample's rest position; H trained on that F's output. "
        "Test take and corpus come from the same simulator (facedyn.sim.tissue, default tissue): an in-simulator figure; "
        "benchmarks/bench_cross_sim.py measures a physics training never saw.")


class Demo:
    def __init__(self, output: Path, scale: str, rig_path: Path | None, data: Path | None, progress: Progress,
                 keep_corpus: bool = False):
        self.output = Path(output)
        self.keep_corpus = keep_corpus
        self.settings = SCALES[scale]
        self.scale = scale
        self.rig_path = rig_path
        self.data = data
        self.progress = progress
        self.timings: dict[str, float] = {}
        self.results: dict = {}

    def step(self, name: str, action):
        print(f"[demo] {name} ...", file=sys.stderr, flush=True)
        started = time.perf_counter()
        value = action()
        self.timings[name] = round(time.perf_counter() - started, 2)
        return value

    def run(self) -> dict:
        from facedyn.processors.corpus_writer import load_rig
        from facedyn.sim.corpus import protocol

        self.output.mkdir(parents=True, exist_ok=True)
        rig = self.step("load rig", lambda: load_rig(self.rig_path))
        specs = protocol(rig, self.settings["corpus"], self.data, seed=0, noise_cm=NOISE_CM)
        description = {"scale": self.scale, "rig": rig.name, "points": rig.point_count, "takes": [s.name for s in specs], "noise_cm": NOISE_CM}
        kept = self.output / "corpus"
        if _existing_corpus(kept) == description:
            print(f"[demo] reusing the corpus in {kept} (same rig, protocol and noise)", file=sys.stderr)
            return self.run_on(rig, kept)
        if self.keep_corpus:
            self.simulate_corpus(kept, rig, specs, description)
            return self.run_on(rig, kept)
        # The corpus (about 1.2 GB at demo scale) only feeds training: by default it lives in a temporary
        # folder that goes when the demo ends, so the output folder holds what a user looks at.
        with tempfile.TemporaryDirectory(prefix="facedyn-demo-corpus-") as scratch:
            corpus = Path(scratch) / "corpus"
            self.simulate_corpus(corpus, rig, specs, description)
            return self.run_on(rig, corpus)

    def simulate_corpus(self, corpus: Path, rig, specs, description: dict) -> None:
        from facedyn.processors.corpus_writer import build_corpus

        self.step(f"simulate corpus ({len(specs)} takes)", lambda: build_corpus(
            corpus, rig, specs, progress=self.progress, description=description, jobs=os.cpu_count() or 1))

    def run_on(self, rig, corpus: Path) -> dict:
        """Every step after the corpus: a new performance through the pipeline, checked against its truth."""
        from facedyn.sim.corpus import TakeSpec, simulate_take
        from facedyn.usd.corpus_files import write_simulated_take

        spec = TakeSpec("performance", "walk", "smile", duration_s=self.settings["seconds"], seed=777, noise_cm=NOISE_CM)
        take_dir = self.output / "take"
        truth = self.step("simulate a new performance", lambda: simulate_take(rig, spec))
        write_simulated_take(take_dir, truth, rig)
        root = take_dir / TAKE_ROOT_FILE
        actor = self.step("make the actor from the rig", lambda: self.make_actor(rig))
        self.stabilize(root, take_dir, truth, rig, actor)
        models = self.output / "models"
        models.mkdir(exist_ok=True)
        self.remove(root, take_dir, truth, rig, corpus, models)
        self.synthesize(root, take_dir, truth, rig, corpus, models)
        self.review(take_dir, rig)
        return self.summary(root)

    def process(self, processor_name: str, inputs: list[Path], output: Path, attach: Path | None = None, **params) -> dict:
        from facedyn.processors import registry
        from facedyn.processors.runner import execute

        request = Request(list(inputs), output, params=params, attach=attach)
        return execute(registry.load(processor_name), request, Progress.silent())

    def make_actor(self, rig) -> Path:
        """The rig as a UsdSkel file and the actor made from it, as a studio makes its actor."""
        from facedyn.usd.blendshape_rig import write_blendshape_rig

        rig_path = self.rig_path or write_blendshape_rig(rig, self.output / "rig.usda")
        actor = self.output / "actor.usda"
        self.process("actor", [rig_path], actor)
        return actor

    def stabilize(self, root, take_dir, truth, rig, actor: Path):
        from facedyn.evaluation import stabilization_errors
        from facedyn.usd.take import read_take

        self.step("stabilize (mode pursuit, actor frame)",
                  lambda: self.process("stabilize", [root], take_dir / "stabilized.usdc", root, actor=actor))
        scratch = take_dir / "baselines"
        scratch.mkdir(exist_ok=True)
        self.step("stabilize (three-point baseline)",
                  lambda: self.process("stabilize", [root], scratch / "three_point.usdc", method="three-point"))
        true_skull = truth.quasistatic + truth.offsets
        errors = {}
        for name, layer in (("mode pursuit", take_dir / "stabilized.usdc"), ("three-point", scratch / "three_point.usdc")):
            solved = _compose(layer, take_dir / role(CAPTURED).layer_file())
            errors[name] = stabilization_errors(*solved.skull(), truth.skull_translate, truth.skull_orient, true_skull,
                                                rig.face_vertices)
        self.results["stabilize"] = errors
        self.stabilized, _ = read_take(root)

    def remove(self, root, take_dir, truth, rig, corpus, models):
        from facedyn.evaluation import residual_fraction
        from facedyn.usd.take import read_take

        model = models / "actor.removal"
        report = self.step("train removal network F", lambda: self.process(
            "train-removal", [corpus], model, skull="truth", target="truth", skull_features="acceleration", sample_positions=True,
            epochs=self.settings["f_epochs"], subsample=self.settings["f_subsample"], batch_size=self.settings["f_batch"]))["summary"]
        self.step("remove dynamics", lambda: self.process("remove", [root], take_dir / "quasistatic.usdc", root, model=str(model)))
        removed, _ = read_take(root)
        self.removed = removed
        face = rig.face_vertices
        self.results["remove"] = {
            "F validation": report["validation"],
            "removed offsets vs true offsets": residual_fraction(removed.offsets, truth.offsets, truth.offsets, face),
            "removed vs true quasistatic": residual_fraction(removed.points, truth.quasistatic, truth.offsets, face),
            "captured vs true quasistatic (do nothing)": residual_fraction(self.stabilized.points, truth.quasistatic, truth.offsets, face),
        }

    def synthesize(self, root, take_dir, truth, rig, corpus, models):
        from facedyn import motion
        from facedyn.evaluation import residual_fraction
        from facedyn.sim.tissue import simulate
        from facedyn.usd.take import read_take

        model = models / "actor.synthesis"
        report = self.step("train synthesis network H", lambda: self.process(
            "train-synthesis", [corpus], model, quasistatic=str(models / "actor.removal"), skull="truth",
            epochs=self.settings["h_epochs"]))["summary"]
        scratch = take_dir / "baselines"
        self.step("re-synthesize under the take's own motion",
                  lambda: self.process("synthesize", [root], scratch / "synthesized.own.usdc", model=str(model)))
        own = _compose(scratch / "synthesized.own.usdc", root)
        self.step("synthesize under a new motion (hop)",
                  lambda: self.process("synthesize", [root], take_dir / "synthesized.hop.usdc", root, model=str(model), skull_motion="hop"))
        hop, _ = read_take(root)
        self.synthesized = hop
        trajectory = motion.hop(duration_s=truth.frames.size / truth.fps, fps=truth.fps, seed=0)
        hop_truth = self.step("simulate the truth under the new motion", lambda: simulate(
            truth.quasistatic, rig.topology.triangles(), trajectory.translate[: truth.frames.size], trajectory.orient[: truth.frames.size],
            truth.fps, rigid_weights=rig.rigid_weights, neutral=rig.neutral))
        face = rig.face_vertices
        self.results["synthesize"] = {
            "H validation": report["validation"],
            "re-synthesized vs captured (own motion)": residual_fraction(own.points, self.stabilized.points, truth.offsets, face),
            "synthesized vs simulated truth (hop)": residual_fraction(hop.offsets, hop_truth.offsets, hop_truth.offsets, face),
        }

    def review(self, take_dir: Path, rig):
        from facedyn.preview.images import write_image
        from facedyn.preview.review import review_sheet
        from facedyn.preview.uvmaps import UVBaker, write_offset_maps

        frames = self.stabilized.frames
        columns = [int(i) for i in np.linspace(len(frames) * 0.2, len(frames) * 0.9, 5)]
        rows = [
            ("captured", self.stabilized.points, self.removed.offsets),
            ("quasistatic", self.removed.points, None),
            ("synthesized (hop)", self.synthesized.points, self.synthesized.offsets),
        ]
        sheet, range_mm = self.step("render the contact sheet", lambda: review_sheet(rows, rig.topology.triangles(), frames, columns))
        self.results["contact_sheet"] = str(write_image(self.output / "contact_sheet.png", sheet))
        maps = self.output / "maps"
        maps.mkdir(exist_ok=True)
        baker = UVBaker(rig.topology, rig.uvs, resolution=512)
        written = self.step("bake EXR uv offset maps", lambda: write_offset_maps(
            maps, "synthesized_offsets", baker, self.synthesized.offsets[columns], frames[columns], self.synthesized.fps,
            f"facedyn {facedyn.__version__}"))
        self.results["offset_maps"] = [str(p) for p in written]

    def summary(self, root: Path) -> dict:
        return {"take": str(root), "scale": self.scale, "path": PATH, "results": self.results, "timings_s": self.timings,
                "total_s": round(sum(self.timings.values()), 1)}


def _existing_corpus(folder: Path) -> dict | None:
    """The description of a corpus an earlier demo run left in `folder`, if any."""
    index = folder / "corpus.json"
    return json.loads(index.read_text()).get("description") if index.is_file() else None


def _compose(*layers: Path):
    """Read the face from layers stacked in memory (strongest first), without a root on disk."""
    from facedyn.usd.take import read_layers

    return read_layers(list(layers))


def format_summary(summary: dict) -> str:
    r = summary["results"]
    lines = ["", "facedyn demo: errors against the simulator's truth (face vertices)", ""]
    lines.append(f"{'stabilize':<44} {'median cm':>10} {'mean cm':>10} {'rot deg':>9} {'trans cm':>9}")
    for name, e in r["stabilize"].items():
        lines.append(f"  {name:<42} {e['median_vertex_cm']:>10.4f} {e['mean_vertex_cm']:>10.4f} {e['mean_rotation_deg']:>9.4f} {e['mean_translation_cm']:>9.4f}")
    lines.append("")
    lines.append(f"{'dynamics (residual RMS / true dynamics RMS)':<44} {'residual cm':>12} {'fraction':>9}")
    for section in ("remove", "synthesize"):
        for name, e in r[section].items():
            if "fraction" in (e or {}):
                lines.append(f"  {name:<42} {e['residual_rms_cm']:>12.4f} {e['fraction']:>8.0%}")
    lines.append("")
    lines.append("what the rows mean (RMS over the face, frames and axes, as a fraction of the true dynamics' RMS):")
    lines += [f"  {name}: {meaning}" for name, meaning in MEANINGS.items()]
    lines.append(PATH)
    lines.append("")
    lines.append("timings (s): " + ", ".join(f"{k} {v}" for k, v in summary["timings_s"].items()))
    lines.append(f"total: {summary['total_s']} s")
    lines.append("")
    lines.append(f"take (open in usdview): {summary['take']}")
    lines.append(f"contact sheet: {r['contact_sheet']}")
    lines.append(f"EXR offset maps: {len(r['offset_maps'])} files, e.g. {r['offset_maps'][0]}")
    return "\n".join(lines)


class DemoProcessor(Processor):
    name = "demo"
    version = "1"
    summary = "run the whole pipeline on the built-in face and report errors against truth"
    reads = Reads("nothing")
    writes = Writes("folder", metavar="DIR", help="the output folder", default="demo-out")
    parameters = (
        Parameter("scale", str, "demo", "corpus and training size (demo: a few minutes)", tuple(SCALES)),
        Parameter("rig", Path, None, "a UsdSkel blend-shape rig instead of the built-in face", metavar="RIG"),
        Parameter("data", Path, None, "a ../shared/data-like folder: adds dialog takes to the corpus", metavar="DIR"),
        Parameter("keep_corpus", bool, False, "keep the simulated corpus (about 1.2 GB) in DIR/corpus, where a later "
                  "demo reuses it; otherwise it is simulated into a temporary folder and removed"),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.sim.corpus import check_data_folder

        params = request.params
        check_data_folder(params["data"], SCALES[params["scale"]]["corpus"])
        return Plan({"scale": params["scale"], "rig": str(params["rig"] or "built-in"), "output": str(request.output),
                     "corpus": str(Path(request.output) / "corpus") if params["keep_corpus"] else "temporary"}, request)

    def run(self, plan: Plan, progress: Progress) -> FolderOutput:
        request = plan.state
        params = request.params
        summary = Demo(request.output, params["scale"], params["rig"], params["data"], progress, params["keep_corpus"]).run()
        (Path(request.output) / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
        return FolderOutput(summary)

    def describe(self, report: dict) -> str:
        return format_summary(report["summary"])
