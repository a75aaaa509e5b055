"""`usdfacedyn train-synthesis`: train network H on a corpus and write the model file.

H learns the dynamics offsets x(t) - y(t) of the corpus takes from their skull motion and
the stretch of their quasistatic skin y(t). As in the paper, y(t) comes from a removal
model F run on the takes (`--quasistatic MODEL`); beyond the paper, a simulated corpus can
give its true quasistatic shapes (`--quasistatic truth`). H reads the skull's landmark
accelerations by default, the paper's velocities with `--skull-features velocity`
(facedyn.dynamics.skull_motion says why).

`--calibrate MODEL` goes on training an existing H (one trained on a simulated corpus of
many tissues) on one actor's own captures instead, through F as the paper does: the actor's
tissue answers the skull in its own way, which a family's average does not
(facedyn.dynamics.synthesis_training.calibrate_synthesis). `--calibrate MODEL --response linear`
fits the actor's linear response to the skull by least squares instead, on takes that each
hold one expression, with neither F nor truth (facedyn.dynamics.response says how); it
keeps the model's setup (an H's, or another response's) and writes a model of kind
"response" (name it .response): synthesize and retarget take it as they take H, remove
takes it as it takes F.
"""
from __future__ import annotations

from functools import partial
from pathlib import Path

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS
from facedyn.processors.base import FileOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.training_inputs import (TRAINING_PARAMETERS, check_session_lengths, epoch_reporter, load_takes, read_truths,
                                                 training_face, training_summary, validation_names)
from facedyn.progress import Progress


class TrainSynthesisProcessor(Processor):
    name = "train-synthesis"
    version = "1"
    summary = "train the synthesis network H on a corpus and write a model file"
    reads = Reads("takes", metavar="CORPUS", help="corpus folders (corpus.json), take folders or stabilized takes")
    writes = Writes("file", metavar="MODEL", help="the model file to write (e.g. actor.synthesis; actor.response with --response linear)")
    parameters = (
        Parameter("quasistatic", str, None, "a removal model (the paper's way) or 'truth' (a simulated corpus's true shapes); "
                  "not with --response linear", metavar="MODEL|truth"),
        Parameter("calibrate", Path, None, "a synthesis model to go on training on these takes (an actor's own captures, "
                  "through --quasistatic F) instead of a new one; it keeps its samples, stretch setup and skull input",
                  metavar="MODEL"),
        Parameter("response", str, "network", "what --calibrate fits: H's network trained on (through --quasistatic), or the "
                  "actor's linear response to the skull by least squares, on takes that each hold one expression", ("network", "linear")),
        Parameter("ridge", float, None, "--response linear: the penalty on the response (default: the one of 0.01, 0.03, 0.1, 0.3 "
                  "and 1 that the session's takes, each left out in turn, prefer; 0.1 for one take)", above=0.0, maximum=1e6,
                  metavar="PENALTY"),
        Parameter("settle", float, 0.4, "--response linear: seconds left out at each take's start, where the expression settles",
                  minimum=0.0, maximum=60.0, metavar="SECONDS"),
        Parameter("epochs", int, None, "training epochs (default: the paper's 30; 100 when calibrating)", minimum=1, maximum=100000),
        Parameter("skull_features", str, "acceleration",
                  "H's skull input: landmark accelerations over t-30..t+10 (beyond the paper), or the paper's velocities over t-10..t+10 "
                  "(calibrating: the model's own)",
                  ("acceleration", "velocity")),
        Parameter("backend", str, "auto", "stretch and feature kernels", BACKENDS),
        *TRAINING_PARAMETERS,
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.dynamics.modelfile import load_model
        from facedyn.usd.errors import TakeError

        params = request.params
        check_sources(params)
        takes = load_takes(request.inputs, params, Progress.silent())
        first = takes[0][1]
        if first.uvs is None and params["calibrate"] is None:  # a calibrated model brings its stretch setup
            raise TakeError(f"{request.inputs[0]}: the takes have no uvs (primvars:st); stretch features need them")
        face, frame = training_face(request.inputs, params, takes)
        if params["quasistatic"] is None:
            quasistatic = None
        elif params["quasistatic"] == "truth":
            truths = read_truths(request.inputs, [name for name, _ in takes])
            quasistatic = {name: truth.points for name, truth in truths.items()}
        else:
            quasistatic = load_model(params["quasistatic"], topology=first.topology, fps=first.fps)
            if quasistatic.kind != "removal":
                raise TakeError(f"{params['quasistatic']}: a {quasistatic.kind} model; --quasistatic needs a removal model or 'truth'")
            if quasistatic.info.get("skull_frame") not in (None, frame["skull_frame"]):
                raise TakeError(f"{params['quasistatic']}: the removal model was trained in another skull frame than these takes'; "
                                "train F and H on takes of one actor")
            face = quasistatic.face  # H uses F's samples and landmarks
        linear = params["response"] == "linear"
        calibrated = None if params["calibrate"] is None else calibration_model(params["calibrate"], first, frame, linear)
        if linear:
            check_session_lengths(takes, calibrated, params["settle"])
        description = {"takes": len(takes), "frames": sum(p.frame_count for _, p in takes), "response": params["response"],
                       "quasistatic": params["quasistatic"], "skull": params["skull"], "epochs": None if linear else epochs_of(params, calibrated),
                       "actor": frame.get("actor"), "calibrate": None if calibrated is None else str(params["calibrate"])}
        return Plan(description, (request, takes, quasistatic, face, frame, calibrated))

    def run(self, plan: Plan, progress: Progress) -> FileOutput:
        from facedyn.dynamics.modelfile import save_model
        from facedyn.dynamics.response import RIDGES, fit_linear_response
        from facedyn.dynamics.skull_motion import NAMED
        from facedyn.dynamics.synthesis_training import calibrate_synthesis, synthesis_config, train_synthesis
        from facedyn.dynamics.training_sequence import TrainingSequence

        request, takes, quasistatic, face, frame, calibrated = plan.state
        params = request.params
        config = synthesis_config(epochs=epochs_of(params, calibrated), validation=validation_names(params), seed=params["seed"],
                                  device=params["device"], skull_motion=NAMED[params["skull_features"]])
        sequences = [TrainingSequence.from_performance(perf, name) for name, perf in takes]
        if params["response"] == "linear":
            penalties = len(RIDGES) if len(takes) > 1 and params["ridge"] is None else 1  # a given ridge, or one take: one fit
            progress.start(f"fit the linear response ({len(takes)} takes, {penalties} ridge penalties)", penalties)
            model = fit_linear_response(calibrated, sequences, settle_s=params["settle"], ridge=params["ridge"],
                                         on_candidate=progress.advance)
            last = None
        elif calibrated is None:
            on_epoch, last = epoch_reporter(progress, f"train H ({len(takes)} takes)", config.epochs)
            model = train_synthesis(sequences, face, takes[0][1].uvs, quasistatic, config, on_epoch, backend=params["backend"])
        else:
            on_epoch, last = epoch_reporter(progress, f"calibrate H ({len(takes)} takes)", config.epochs)
            model = calibrate_synthesis(calibrated, sequences, quasistatic, config, on_epoch, backend=params["backend"])
        progress.finish()
        model.info.update(frame)
        record = model.info["calibration"] if calibrated is not None else model.info["training"]
        record.update(skull=params["skull"], inputs=[str(p) for p in request.inputs], quasistatic=params["quasistatic"])
        summary = {**training_summary(model, takes, face if calibrated is None else calibrated.face, last), "quasistatic": params["quasistatic"],
                   "response": params["response"]}
        if params["response"] == "linear":
            summary["session_cross_validated_left"] = record["session_cross_validated_left"]
            summary["ridge"] = record["ridge"]
            summary["hardening"] = record["hardening"]
        return FileOutput(partial(save_model, model), summary)


def check_sources(params: dict) -> None:
    """--quasistatic for a network, none for a linear response, which needs --calibrate's setup."""
    if params["response"] == "linear":
        if params["calibrate"] is None:
            raise UsageError("--response linear needs --calibrate MODEL: the synthesis model whose samples, stretch setup and "
                             "skull input the linear response takes")
        if params["quasistatic"] is not None:
            raise UsageError("--response linear fits held expressions without a quasistatic source; leave out --quasistatic")
        if params["epochs"] is not None:
            raise UsageError("--epochs trains a network; --response linear is fitted by least squares")
    elif params["ridge"] is not None:
        raise UsageError("--ridge is the linear response's penalty; give it with --response linear")
    elif params["quasistatic"] is None:
        raise UsageError("--quasistatic MODEL|truth is required: what gives the takes' quasistatic shapes")


def epochs_of(params: dict, calibrated) -> int:
    """--epochs, else the paper's 30 for a new H and CALIBRATION_EPOCHS for a calibration."""
    from facedyn.dynamics.synthesis_training import CALIBRATION_EPOCHS, EPOCHS

    return params["epochs"] or (EPOCHS if calibrated is None else CALIBRATION_EPOCHS)


def calibration_model(path: Path, first, frame: dict, linear: bool = False):
    """The synthesis model to calibrate (for a linear response, also a response: its setup is
    the same), checked against the takes: topology, frame rate and skull frame."""
    from facedyn.dynamics.modelfile import load_model
    from facedyn.usd.errors import TakeError

    model = load_model(path, topology=first.topology, fps=first.fps)
    if model.kind not in (("synthesis", "response") if linear else ("synthesis",)):
        raise TakeError(f"{path}: a {model.kind} model; --calibrate needs a synthesis model (network H)"
                        f"{' or a linear response' if linear else ''}")
    if model.info.get("skull_frame") not in (None, frame["skull_frame"]):
        raise TakeError(f"{path}: the synthesis model was trained in another skull frame than these takes'; stabilize the "
                        "calibration takes with the --actor the model was trained for")
    return model
