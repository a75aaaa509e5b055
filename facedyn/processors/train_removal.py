"""`usdfacedyn train-removal`: train network F on a corpus and write the model file.

Its output is a model (weights + JSON metadata, facedyn.dynamics.modelfile), the input of
the remove processor. The takes are checked from their first frames, then read one at a
time into the trainer's store, so memory holds one take (and the store's sample columns),
not the corpus. `--budget-minutes` stops training before an epoch that would end past it.
"""
from __future__ import annotations

import time
from functools import partial

from facedyn.errors import UsageError
from facedyn.processors.base import FileOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.training_inputs import (TRAINING_PARAMETERS, epoch_reporter, select_takes, take_heads, training_face,
                                                 training_sequences, training_summary, validation_names)
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
        Parameter("budget_minutes", float, None, "stop before an epoch that would end later than this many minutes from the "
                  "start, reading the takes included (default: train every epoch; with it, the epochs depend on the machine's "
                  "speed)", above=0.0, maximum=100000.0, metavar="MINUTES"),
        *TRAINING_PARAMETERS,
    )

    def prepare(self, request: Request) -> Plan:
        params = request.params
        if params["target"] == "truth" and params["skull"] != "truth":
            raise UsageError("--target truth needs --skull truth: the true dynamics are vectors in the true skull's frame, "
                             "which a solved skull matches only up to an unknown rigid transform")
        started = time.monotonic()
        named = select_takes(request.inputs, params)
        heads = take_heads(named, params["skull"])
        face, frame = training_face(request.inputs, params, [(name, head) for name, head, _ in heads])
        description = {"takes": len(heads), "frames": sum(frames for _, _, frames in heads), "target": params["target"],
                       "skull": params["skull"], "epochs": params["epochs"], "actor": frame.get("actor"),
                       "budget_minutes": params["budget_minutes"]}
        return Plan(description, (request, named, face, frame, started))

    def run(self, plan: Plan, progress: Progress) -> FileOutput:
        from facedyn.dynamics.modelfile import save_model
        from facedyn.dynamics.skull_motion import NAMED
        from facedyn.dynamics.training import TrainConfig, train_removal

        request, named, face, frame, started = plan.state
        params = request.params
        minutes = params["budget_minutes"]
        config = TrainConfig(epochs=params["epochs"], subsample=params["subsample"], batch_size=params["batch_size"], validation=validation_names(params),
                             seed=params["seed"], device=params["device"], target=params["target"], sample_positions=params["sample_positions"],
                             skull_motion=NAMED[params["skull_features"]] if params["skull_features"] == "acceleration" else None,
                             time_limit_s=None if minutes is None else minutes * 60.0)
        training = training_sequences(named, params["skull"], params["target"] == "truth")
        on_epoch, last = epoch_reporter(progress, f"train F ({len(named)} takes; the first epoch reads them)", config.epochs)
        model = train_removal(training, face, config, on_epoch, started=started)
        trained = len(model.info["loss_curve"])
        if trained < config.epochs:
            progress.note(f"stopped after {trained} of {config.epochs} epochs: the next would end past --budget-minutes {minutes:g}")
        progress.finish()
        model.info.update(frame)
        model.info["training"]["skull"] = params["skull"]
        model.info["training"]["inputs"] = [str(p) for p in request.inputs]
        return FileOutput(partial(save_model, model), training_summary(model, named, face, last))
