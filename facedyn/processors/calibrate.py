"""`usdfacedyn calibrate`: an actor's removal and synthesis models from its rig and session, in one command.

The README's workflow for a real actor, as one resumable run within a stated budget:

1. `corpus/`: the family corpus simulated on the actor's rig with the recommended protocol
   (standard scale, tissue drawn per take, extra motions, foot-contact impacts, 0.1 mm of
   tracking noise, the Live Link performances with `--data`; facedyn.processors.corpus_writer.build_corpus);
2. `family.removal`: the family's F trained on it with the recommended flags (true skull and
   targets, skull accelerations, sample positions, batches of 2,000), epochs of `--subsample`
   of the pairs until the minutes the corpus left, less a reserve for stages 3 and 4 sized by
   the session (RESERVE_S_PER_POINT_FRAME), are spent (train-removal
   --budget-minutes: it stops before an epoch that would end later, at most MAX_EPOCHS): so
   the default's epochs depend on the machine's speed and load, and `--epochs` pins them
   (the same model on the same machine);
3. `synthesis.response`: the actor's linear response fitted on the session, its ridge
   chosen there (facedyn.dynamics.response), with F's samples and landmarks, and the
   actor's spread from those samples to the mesh learned on the session's skin motion
   (facedyn.dynamics.spread), which every model calibrate writes for the actor carries;
4. the removal chosen without truth: each candidate (the family's F, the response, the mean
   of the two, and the two weighed per frequency band) scored on the session by `evaluate
   --session`'s figure, the fraction of the held takes' motion it leaves (the response's own
   takes each removed by the response refitted without it, so its figure is a new
   capture's), all in one pass over the session (each take read and cleaned of tracker
   spikes once). The band weights are the ones that leave the least (a weight per octave band
   for F, the rest the response's: facedyn.dynamics.bands), so that candidate leaves at most
   what the other three do on the session and differs from them as far as the session
   says the two models are better at different frequencies. The least-leaving is written
   as `removal.removal`, `removal.response` or `removal.blend` (a blend file holding both
   models and, for the bands, their weights), which `remove --model` takes;
5. `calibration.json`: every candidate's figure, the choice, the budget (F's minutes, the
   epochs trained with their measured seconds and pairs a second) and the time each stage took.

Each stage's outputs are written atomically into the folder and recorded in
`stages.json`; a re-run skips the stages already done with the same inputs, so an
interrupted calibration resumes (facedyn.processors.stages). The session's takes must be
stabilized with the actor made from the rig (`usdfacedyn actor RIG`, `stabilize --actor`):
that is the skull frame the corpus is simulated in.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import replace
from pathlib import Path

from facedyn.errors import UsageError
from facedyn.io.files import write_atomically
from facedyn.performance import TAKE_ROOT_FILE
from facedyn.processors.base import FolderOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.epoch_clock import EpochClock
from facedyn.progress import Progress

BUDGET_MINUTES = 45.0  # the whole command's, by default: the target for a 70-take session of a 2.7k-point rig on 2 cores
RESERVE_S_PER_POINT_FRAME = 6.5e-6  # kept after F for the response, its spread and the scores, per session point-frame:
# twice the 2.5 us the response and the scores took on the 70-take session of the 2,735-point ARKit rig (133 s + 98 s +
# the bands, 37,800 frames, idle) and the 0.65 us of the spread (28 s on test_default_3104's 70 takes of 4,058 points)
RESERVE_MIN_S = 60.0  # and at least this
MAX_EPOCHS = 250  # the paper's
CANDIDATES = ("family", "response", "mean", "bands")  # the removals scored, in the order a tie keeps
NOISE_CM = 0.01  # the recommended corpus's tracking noise
F_SAMPLES = 344  # F's skin samples (train-removal's default): the pairs per corpus frame


class CalibrateProcessor(Processor):
    name = "calibrate"
    version = "1"
    summary = "an actor's removal and synthesis models from its rig and calibration session, the removal chosen on the session"
    reads = Reads("takes", metavar="TAKE", help="the session's stabilized take roots, each holding one expression under a motion")
    writes = Writes("folder", metavar="DIR", help="the folder for the models, calibration.json and each stage's outputs "
                    "(a re-run resumes in it)", resumable=True)
    parameters = (
        Parameter("rig", Path, help="the actor's UsdSkel blend-shape rig, which the family corpus is simulated on", metavar="RIG"),
        Parameter("budget_minutes", float, BUDGET_MINUTES, "the whole calibration's time: F trains for its share of what the corpus "
                  "leaves",
                  above=0.0, maximum=100000.0, metavar="MINUTES"),
        Parameter("epochs", int, None, "F's training epochs (default: as many as fit its share of the budget on this machine, "
                  "so they depend on it; at most 250)", minimum=1, maximum=100000),
        Parameter("subsample", float, 0.5, "fraction of the corpus's (frame, sample) pairs F draws each epoch", above=0.0, maximum=1.0),
        Parameter("data", Path, None, "a ../shared/data-like folder: the corpus adds the Live Link performances (recommended)",
                  metavar="DIR"),
        Parameter("corpus_scale", str, "standard", "the corpus protocol's size", ("demo", "standard")),
        Parameter("corpus_only", str, "", "only corpus takes whose name matches this glob pattern", metavar="PATTERN"),
        Parameter("seed", int, 0, "seed of the corpus and of F's training", minimum=0, maximum=2**32 - 1),
        Parameter("jobs", int, os.cpu_count() or 1, "corpus takes simulated at once", minimum=1, maximum=1024),
        Parameter("ridge", float, None, "the response's penalty (default: the session's choice)", above=0.0, maximum=1e6, metavar="PENALTY"),
        Parameter("settle", float, 0.4, "seconds left out at each session take's start for the response, where the expression settles",
                  minimum=0.0, maximum=60.0, metavar="SECONDS"),
        Parameter("skip", float, 0.5, "seconds left out at each session take's start in the candidates' scores", minimum=0.0,
                  maximum=60.0, metavar="SECONDS"),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.performance import QUASISTATIC, skull_frame_id
        from facedyn.processors.training_inputs import take_name, take_skull_frame
        from facedyn.usd.errors import TakeError
        from facedyn.usd.frames import TakeFrames
        from facedyn.usd.blendshape_rig import read_blendshape_rig
        from facedyn.usd.training_data import take_roots

        params = request.params
        if len(request.inputs) < 2:
            raise UsageError("give the session's take roots, at least two: the response is chosen by leaving each take out")
        roots = [root / TAKE_ROOT_FILE if root.is_dir() else root for root in take_roots(request.inputs)]
        if not params["rig"].is_file():
            raise UsageError(f"--rig {params['rig']}: no such file")
        rig = read_blendshape_rig(params["rig"])
        frame = skull_frame_id(rig.neutral, rig.topology)
        readers = {root: TakeFrames(root, QUASISTATIC) for root in roots}
        heads = {root: reader.head for root, reader in readers.items()}
        rates = sorted({round(head.fps, 6) for head in heads.values()})
        if len(rates) > 1:
            raise UsageError(f"the session's takes run at {', '.join(f'{r:g}' for r in rates)} fps; a model serves one rate: "
                             f"import them at one rate (usdfacedyn import CAPTURE --fps RATE)")
        # the corpus is simulated at the session's rate, so F and the response read the session's frames as they trained
        specs = [replace(spec, fps=rates[0]) for spec in corpus_specs(rig, params)]
        for root, head in heads.items():
            if head.skull_orient is None:
                raise TakeError(f"{root}: no solved skull; stabilize the session's takes first (stabilize --actor ACTOR)")
            if head.topology.fingerprint() != rig.topology.fingerprint():
                raise TakeError(f"{root}: its mesh is not the rig's ({params['rig']}); calibrate one actor's takes with its own rig")
            if take_skull_frame(head) != frame:
                raise TakeError(f"{root}: the take is not in the rig's skull frame; stabilize it with --actor ACTOR, the actor made "
                                f"from the rig (usdfacedyn actor {params['rig']} -o actor.usda)")
        names = [take_name(root) for root in roots]
        if len(set(names)) != len(names):
            raise UsageError(f"two session takes share a name ({', '.join(sorted({n for n in names if names.count(n) > 1}))}); "
                             "each take's folder names it")
        point_frames = sum(reader.frame_count for reader in readers.values()) * rig.point_count
        description = {"session_takes": len(roots), "session_point_frames": point_frames, "rig": str(params["rig"]),
                       "points": rig.point_count, "corpus_takes": len(specs), "corpus_fps": specs[0].fps,
                       "budget_minutes": params["budget_minutes"], "epochs": params["epochs"] or "from the budget"}
        return Plan(description, (request, roots, rig, specs, point_frames))

    def run(self, plan: Plan, progress: Progress) -> FolderOutput:
        from facedyn.dynamics.bands import EDGES_HZ
        from facedyn.dynamics.spread import RANK as SPREAD_RANK, RIDGE as SPREAD_RIDGE
        from facedyn.io.files import sha256_of_file
        from facedyn.processors.stages import Stages, file_state, key_of

        request, roots, rig, specs, point_frames = plan.state
        params = request.params
        out = Path(request.output)
        out.mkdir(parents=True, exist_ok=True)
        stages = Stages(out, progress)
        started = time.perf_counter()
        session = file_state(roots)
        corpus_key = key_of("corpus", sha256_of_file(params["rig"]), [s.name for s in specs], specs[0].fps, corpus_description(params))
        corpus = stages.run("corpus", corpus_key, [out / "corpus"], lambda: build_family_corpus(out / "corpus", rig, specs, params, progress),
                            resumes=True)
        spent = stages.seconds().get("corpus", time.perf_counter() - started)
        budget = training_budget(params, corpus, spent, point_frames)
        limit = (f"{budget['epochs']} epochs" if budget["epochs_given"] else
                 f"{budget['training_seconds_planned'] / 60:.1f} min (at most {budget['epochs']} epochs)")
        progress.note(f"budget {params['budget_minutes']:g} min: F trains {limit} of {budget['subsample']:.0%} of {budget['pairs']:,} pairs")
        family_key = key_of("family", corpus_key, budget["epochs"], budget["training_seconds_planned"], budget["subsample"], params["seed"])
        family = stages.run("family", family_key, [out / "family.removal"],
                            lambda: train_family(out / "corpus", out / "family.removal", budget, corpus, params, progress))
        response_key = key_of("response", family_key, session, params["ridge"], params["settle"], {"spread": [SPREAD_RIDGE, SPREAD_RANK]})
        response = stages.run("response", response_key, [out / "synthesis.response"],
                              lambda: fit_response(roots, out / "family.removal", out / "synthesis.response", params, progress))
        both = (out / "family.removal", out / "synthesis.response")
        models = {"family": (out / "family.removal",), "response": (out / "synthesis.response",), "mean": both, "bands": both}
        scores_key = key_of("scores", family_key, response_key, session, params["skip"], EDGES_HZ)
        figures = stages.run("scores", scores_key, [], lambda: score_candidates(roots, out / "family.removal", out / "synthesis.response",
                                                                                params, progress))
        chosen = min(CANDIDATES, key=lambda name: figures[name]["session_motion_left"])
        removal = write_removal(out, chosen, figures["bands"]["weights"])
        record = {"chosen": chosen, "removal": removal.name, "synthesis": "synthesis.response",
                  "candidates": {name: {"models": [p.name for p in models[name]], **figures[name]}
                                 for name in CANDIDATES},
                  "response": response, "budget": {**budget, "budget_minutes": params["budget_minutes"]}, "family": family,
                  "stage_seconds": stages.seconds(), "rig": str(params["rig"]), "session": [str(r) for r in roots],
                  "corpus": corpus}
        text = json.dumps(record, indent=2, sort_keys=True).encode() + b"\n"
        write_atomically(out / "calibration.json", lambda handle: handle.write(text))
        return FolderOutput({"chosen": chosen, "removal": str(removal), "synthesis": str(out / "synthesis.response"),
                             **{f"{name}_session_motion_left": figures[name]["session_motion_left"] for name in CANDIDATES},
                             "epochs": family["epochs"], "subsample": budget["subsample"], "pairs_per_second": family["pairs_per_second"],
                             "calibration": str(out / "calibration.json")})

    def describe(self, report: dict) -> str:
        summary = report["summary"]
        return "\n".join(f"{k}: {v}" for k, v in summary.items())


def corpus_description(params: dict) -> dict:
    """The recommended corpus's flags, as `simulate` records them; paths resolved, so a re-run that
    names the same rig or data folder another way keeps the stages done (and F's hours)."""
    return {"scale": params["corpus_scale"], "rig": str(Path(params["rig"]).resolve()), "noise_cm": NOISE_CM, "seed": params["seed"],
            "physics": "tissue", "randomize_tissue": "take", "extra_motions": True, "impacts": True,
            "data": str(Path(params["data"]).resolve()) if params["data"] else "", "only": params["corpus_only"]}


def corpus_specs(rig, params: dict) -> list:
    """The recommended protocol's takes (README: synth --scale standard --randomize-tissue take --extra-motions --impacts
    --noise 0.01 --data DATA)."""
    from facedyn.processors.corpus_writer import protocol_takes

    return protocol_takes(rig, params["corpus_scale"], params["data"], params["corpus_only"], "--corpus-only", seed=params["seed"],
                          noise_cm=NOISE_CM, physics="tissue", randomize_tissue="take", extra_motions=True, impacts=True)


def build_family_corpus(folder: Path, rig, specs: list, params: dict, progress: Progress) -> dict:
    """Stage 1: the family corpus (facedyn.processors.corpus_writer.build_corpus); its size for the record."""
    from facedyn.processors.corpus_writer import build_corpus

    index = build_corpus(folder, rig, specs, progress=progress, description=corpus_description(params), jobs=params["jobs"])
    return {"takes": len(index["takes"]), "failed": len(index["failed"]), "frames": int(index["frames"])}


def training_budget(params: dict, corpus: dict, spent_seconds: float, session_point_frames: int) -> dict:
    """F's epochs and subsample: --epochs, else epochs of --subsample of the corpus's pairs for the
    minutes the corpus left less the reserve the response and the scores need on this session
    (RESERVE_S_PER_POINT_FRAME, at least RESERVE_MIN_S; F gets at least a second: one epoch), at most MAX_EPOCHS."""
    given = params["epochs"] is not None
    left_s = max(params["budget_minutes"] * 60.0 - spent_seconds, 0.0)
    reserve_s = max(RESERVE_S_PER_POINT_FRAME * session_point_frames, RESERVE_MIN_S)
    return {"epochs": params["epochs"] if given else MAX_EPOCHS, "epochs_given": given, "subsample": params["subsample"],
            "pairs": corpus["frames"] * F_SAMPLES, "reserve_seconds": round(reserve_s, 1),
            "training_seconds_planned": None if given else round(max(left_s - reserve_s, 1.0), 1)}


def train_f(inputs: list[Path], output: Path, epochs: int, seconds: float | None, params: dict, progress: Progress) -> EpochClock:
    """F trained with train-removal's recommended flags, for `epochs` or until `seconds` are spent; the clock of its epochs."""
    from facedyn.processors import registry
    from facedyn.processors.runner import execute

    clock = EpochClock(progress)
    execute(registry.load("train-removal"), Request(inputs, output, params={
        "skull": "truth", "target": "truth", "skull_features": "acceleration", "sample_positions": True, "batch_size": 2000,
        "epochs": epochs, "budget_minutes": None if seconds is None else seconds / 60.0, "subsample": params["subsample"],
        "seed": params["seed"]}), clock)
    return clock


def train_family(corpus: Path, output: Path, budget: dict, size: dict, params: dict, progress: Progress) -> dict:
    """Stage 2: the family's F with train-removal's recommended flags, for the budget's epochs or
    minutes; what its epochs took (the first includes reading the takes into the feature store)
    and its throughput in (frame, sample) pairs drawn a second, over the epochs after the first."""
    import statistics

    started = time.perf_counter()
    epochs = train_f([corpus], output, budget["epochs"], budget["training_seconds_planned"], params, progress).epoch_seconds()
    steady = statistics.median(epochs[1:] or epochs)
    return {"seconds": round(time.perf_counter() - started, 1), "epochs": len(epochs), "first_epoch_seconds": epochs[0],
            "median_epoch_seconds": round(steady, 3),
            "pairs_per_second": round(size["frames"] * F_SAMPLES * params["subsample"] / max(steady, 1e-6), 1)}


def fit_response(roots: list, family: Path, output: Path, params: dict, progress: Progress) -> dict:
    """Stage 3: the actor's linear response on the session, with F's samples and landmarks."""
    from facedyn.dynamics.modelfile import load_model, save_model
    from facedyn.dynamics.response import RIDGES, fit_linear_response, response_template
    from facedyn.dynamics.spread import fit_model_spread
    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.processors.training_inputs import check_session_lengths, load_takes

    takes = load_takes(roots, {"include": "", "exclude": "", "validation": "", "skull": "take"}, progress)
    f = load_model(family, topology=takes[0][1].topology, fps=takes[0][1].fps)
    frame = {key: f.info[key] for key in ("skull_frame", "actor") if key in f.info}
    template = response_template(f.face, f.fps, frame)
    check_session_lengths(takes, template, params["settle"])
    progress.start(f"fit the linear response ({len(takes)} takes)", len(RIDGES) if params["ridge"] is None else 1)
    sequences = [TrainingSequence.from_performance(perf, name) for name, perf in takes]
    model = fit_linear_response(template, sequences, settle_s=params["settle"], ridge=params["ridge"], on_candidate=progress.advance)
    progress.finish()
    progress.start(f"learn the spread from the samples on the session ({len(takes)} takes)", 1)
    model = fit_model_spread(model, sequences, params["settle"])
    progress.finish()
    model.info["calibration"].update(skull="take", inputs=[str(r) for r in roots])
    save_model(model, output)
    record = model.info["calibration"]
    return {**{key: record[key] for key in ("ridge", "ridge_candidates", "session_cross_validated_left", "hardening")},
            "spread": model.info["spread"]}


def score_candidates(roots: list, family: Path, response: Path, params: dict, progress: Progress) -> dict:
    """Stage 4: what each candidate removal leaves of the session's motion (`evaluate --session`'s
    figure), in one pass: each take read once, removed by the family's F and by the response
    refitted without it (remove_left_out), the mean of the two as a blend averages them."""
    import numpy as np

    from facedyn.dynamics.modelfile import load_model
    from facedyn.dynamics.response import remove_left_out
    from facedyn.dynamics.spread import spread_of, with_spread
    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.performance import QUASISTATIC
    from facedyn.processors.model_steps import removal_of, session_motion_left
    from facedyn.processors.training_inputs import take_name
    from facedyn.usd.take import read_take_below

    takes = [read_take_below(root, QUASISTATIC)[0] for root in roots]  # the stabilized takes, as remove reads them
    actor = load_model(response, topology=takes[0].topology, fps=takes[0].fps)
    f = with_spread(load_model(family, topology=takes[0].topology, fps=takes[0].fps), *spread_of(actor))
    left_out = remove_left_out(actor, [TrainingSequence.from_performance(perf, take_name(root)) for root, perf in zip(roots, takes)])

    def removals():
        for perf, (_, by_response) in zip(takes, left_out):
            _, by_family = removal_of(perf.points, *perf.skull(), perf.fps, f)
            yield perf, {"family": by_family, "response": by_response,
                         "mean": np.mean([by_family, by_response], axis=0).astype(np.float32)}  # as BandWeights.mean(2) blends them
            progress.advance()

    progress.start(f"score {', '.join(CANDIDATES)} on the session ({len(takes)} takes)", len(takes))
    figures = session_motion_left(removals(), ("family", "response", "mean"), params["skip"], band_pair=("family", "response"))
    progress.finish()
    return {**{name: {"session_motion_left": figures[name]} for name in CANDIDATES},
            "bands": {"session_motion_left": figures["bands"], "weights": figures["band_weights"].to_json()}}


def write_removal(out: Path, chosen: str, band_weights: dict) -> Path:
    """The chosen removal as one model file `removal.<suffix>` that `remove --model` takes (the
    bands: a blend with `band_weights`, facedyn.dynamics.bands.BandWeights' record); any other
    removal.* a run before chose is removed (after the new one is in place)."""
    from facedyn.dynamics.bands import BandWeights
    from facedyn.dynamics.modelfile import SUFFIXES, load_model, save_blend, save_model
    from facedyn.dynamics.spread import spread_of, with_spread

    actor = load_model(out / "synthesis.response")
    family = with_spread(load_model(out / "family.removal"), *spread_of(actor))  # the family's F, spread as this actor's skin moves
    if chosen in ("mean", "bands"):
        weights = BandWeights.from_json(band_weights) if chosen == "bands" else None
        path = save_blend([family, actor], out / f"removal{SUFFIXES['blend']}", weights)
    elif chosen == "family":
        path = save_model(family, out / f"removal{SUFFIXES['removal']}")
    else:
        data = (out / "synthesis.response").read_bytes()
        path = write_atomically(out / f"removal{SUFFIXES['response']}", lambda handle: handle.write(data))
    for other in SUFFIXES.values():
        if out / f"removal{other}" != path and (out / f"removal{other}").exists():
            (out / f"removal{other}").unlink()
    return path
