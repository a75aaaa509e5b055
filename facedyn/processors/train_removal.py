"""`usdfacedyn train-removal`: train network F on a corpus and write the model file.

Its output is a model (weights + JSON metadata, facedyn.dynamics.modelfile), the input of
the remove processor.
"""
from __future__ import annotations

from dataclasses import replace
from functools import partial

from facedyn.errors import UsageError
from facedyn.processors.base import FileOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.training_inputs import (TRAINING_PARAMETERS, epoch_reporter, load_takes, read_truths, training_face,
                                                 training_summary, validation_names)
from facedyn.progress import Progress


class TrainRemovalProcessor(Processor):
    name = "train-removal"
    version = "1"
    summary = "train the removal network F on a corpus and write a model file"
    reads = Reads("takes", metavar="CORPUS", help="corpus folders (corpus.json), take folders or stabilized takes")
    writes = Writes("file", metavar="MODEL", help="the model file to write (e.g. actor.removal)")
    parameters = (
        Parameter("epochs", int, 250, "training epochs (the paper trains 250)", minimum=1, maximum=100000),
        Parameter("subsample", float, 1.0, "fraction of the (frame, sample) pairs drawn each epoch", above=0.0, maximum=1.0),
        Parameter("batch_size", int, 10_000, "(frame, sample) pairs per optimizer step (the paper's 10,000; a short budget "
                  "learns more from smaller batches)", minimum=1, maximum=10_000_000),
        Parameter("target", str, "moving-average",
                  "F's targets: the paper's moving-average offsets, or a simulated corpus's true dynamics (with --skull truth)",
                  ("moving-average", "truth")),
        Parameter("skull_features", str, "velocity",
                  "F's skull input: the paper's landmark velocities over t-10..t+10, or accelerations over t-30..t+10",
                  ("velocity", "acceleration")),
        Parameter("sample_positions", bool, False,
                  "F also reads each skin sample's rest position (where on the face it is; beyond the paper)"),
        *TRAINING_PARAMETERS,
    )

    def prepare(self, request: Request) -> Plan:
        params = request.params
        if params["target"] == "truth" and params["skull"] != "truth":
            raise UsageError("--target truth needs --skull truth: the true dynamics are vectors in the true skull's frame, "
                             "which a solved skull matches only up to an unknown rigid transform")
        takes = load_takes(request.inputs, params, Progress.silent())
        truths = read_truths(request.inputs, [name for name, _ in takes]) if params["target"] == "truth" else None
        face, frame = training_face(request.inputs, params, takes)
        description = {"takes": len(takes), "frames": sum(p.frame_count for _, p in takes), "target": params["target"],
                       "skull": params["skull"], "epochs": params["epochs"], "actor": frame.get("actor")}
        return Plan(description, (request, takes, truths, face, frame))

    def run(self, plan: Plan, progress: Progress) -> FileOutput:
        from facedyn.dynamics.modelfile import save_model
        from facedyn.dynamics.skull_motion import NAMED
        from facedyn.dynamics.training import TrainingSequence, TrainConfig, train_removal

        request, takes, truths, face, frame = plan.state
        params = request.params
        config = TrainConfig(epochs=params["epochs"], subsample=params["subsample"], batch_size=params["batch_size"], validation=validation_names(params),
                             seed=params["seed"], device=params["device"], target=params["target"], sample_positions=params["sample_positions"],
                             skull_motion=NAMED[params["skull_features"]] if params["skull_features"] == "acceleration" else None)
        training = [TrainingSequence.from_performance(perf, name) for name, perf in takes]
        if truths is not None:
            training = [replace(take, dynamics=truths[take.name].offsets) for take in training]
        on_epoch, last = epoch_reporter(progress, f"train F ({len(takes)} takes)", config.epochs)
        model = train_removal(training, face, config, on_epoch)
        progress.finish()
        model.info.update(frame)
        model.info["training"]["skull"] = params["skull"]
        model.info["training"]["inputs"] = [str(p) for p in request.inputs]
        return FileOutput(partial(save_model, model), training_summary(model, takes, face, last))
