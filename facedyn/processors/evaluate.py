"""`usdfacedyn evaluate`: truth-free diagnostics of removal (and synthesis) on real captures.

Reads takes after `remove` (the quasistatic take: the layers below the synthesized role,
with the removed offsets), and writes a folder with `report.json` (the numbers) and
`diagnostics.png` (the spectra and the held expression's deviation over time). Per take:
the removed offsets' spectrum against the skull's (facedyn.dynamics.diagnostics), the
fraction of the capture's motion left at the skull's frequency (a platform take's
frequency: give one training never saw for a held-out check), and with `--synthesis`
the re-synthesis residual against the capture. With `--held-expression`, the takes hold
one expression under different motions: the spread of its shape after removal against
the spread of the capture. With `--session`, the takes are an actor's calibration session,
each holding one expression: the fraction of their motion beyond the held shapes and the
sag that follows the head that the removal leaves (the number `train-synthesis --response
linear` records for the actor's linear response, by leaving each take out). With `--removal MODEL`, the takes are read as `remove` reads them
(stabilized) and that model's removal is evaluated, in memory: candidate models compare on
one session without attaching (or writing) any layer. MODEL may be a removal model (F), an
actor's linear response or a blend file (whose members' removals are averaged); given the response's own calibration takes, each is removed by
the response refitted without it (facedyn.dynamics.response.remove_left_out), so its
figures are those of a new capture. `--blend MODEL` evaluates the mean of the two models'
removals, as `remove --blend` makes it.
"""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import QUASISTATIC, SYNTHESIZED
from facedyn.processors.base import FolderOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.model_steps import SYNTHESIZES, check_skull_frame, removal_blend, removal_of, session_motion_left
from facedyn.progress import Progress

QUASISTATIC_BELOW = SYNTHESIZED  # evaluate reads what remove wrote: everything below the synthesized role
REMOVAL_READS = QUASISTATIC  # with --removal, evaluate reads what remove reads: everything below its own role
MAX_FRAMES = 10_000  # frames of a take evaluate reads (whole, for its spectra): about 2 GB at 4,000 points


class EvaluateProcessor(Processor):
    name = "evaluate"
    version = "1"
    summary = "truth-free diagnostics of removed dynamics on captures (numbers and a plot)"
    reads = Reads("takes", metavar="TAKE", help="take roots after remove (one or more)", frame_range=True)
    writes = Writes("folder", metavar="DIR", help="the folder for report.json and diagnostics.png")
    parameters = (
        Parameter("held_expression", bool, False, "the takes hold one expression under different motions: report its spread"),
        Parameter("session", bool, False, "the takes are a calibration session, each holding one expression: report how much of "
                  "their motion beyond the held shapes and the head-following sag the removal leaves"),
        Parameter("skip", float, 0.5, "seconds at the start of each take left out of the spread and the session (the expression easing in)",
                  minimum=0.0, maximum=60.0, metavar="S"),
        Parameter("frequency", float, None, "the frequency (Hz) whose residual to report (default: the skull motion's peak)",
                  above=0.0, maximum=1000.0, metavar="HZ"),
        Parameter("synthesis", Path, None, "a synthesis model (H or a linear response): also re-synthesize each take under its own "
                  "motion", metavar="MODEL"),
        Parameter("removal", Path, None, "evaluate this removal model (F, an actor's linear response or a blend) on the stabilized takes "
                  "instead of the removal they carry (nothing is written to them)", metavar="MODEL"),
        Parameter("blend", Path, None, "with --removal: evaluate the mean of its removal and this model's (as remove --blend)",
                  metavar="MODEL"),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.errors import TakeError
        from facedyn.usd.take import read_take_below

        if not request.inputs:
            raise UsageError("give at least one TAKE")
        params = request.params
        if params["blend"] is not None and params["removal"] is None:
            raise UsageError("--blend MODEL averages with --removal MODEL's removal; give --removal too")
        takes = []
        removals, weights = [], None
        reads = QUASISTATIC_BELOW if params["removal"] is None else REMOVAL_READS
        for path in request.inputs:
            check_length(path, reads, request.frames)
            perf, _ = read_take_below(path, reads, frames=request.frames)
            if params["removal"] is not None and not removals:
                removals, weights = removal_blend(params["removal"], params["blend"], perf, perf.fps, path)
            elif params["removal"] is not None:
                for model_path, model in removals:
                    check_skull_frame(path, perf, model_path, model)
            elif perf.offsets is None:
                raise TakeError(f"{path}: no removed offsets (primvars:facedyn:dynamicsOffset); run `usdfacedyn remove` first")
            if perf.frame_count < 8:
                raise TakeError(f"{path}: {perf.frame_count} frames; the diagnostics need at least 8")
            if takes and perf.topology.fingerprint() != takes[0][1].topology.fingerprint():
                raise TakeError(f"{path}: its mesh topology differs from {request.inputs[0]}'s; evaluate one actor's takes")
            takes.append((Path(path), perf))
        if params["held_expression"] and len(takes) < 2:
            raise UsageError("--held-expression compares takes: give at least two")
        for model_path, model in removals:
            check_response_takes(model_path, model, takes)
        removals = [model for _, model in removals]
        synthesis = None if params["synthesis"] is None else fitting_model(params["synthesis"], takes[0][1], "synthesis")
        description = {"takes": [str(p) for p, _ in takes], "frames": [p.frame_count for _, p in takes],
                       "held_expression": params["held_expression"], "session": params["session"], "synthesis": str(params["synthesis"] or ""),
                       "removal": str(params["removal"] or "the takes' own"), "blend": str(params["blend"] or "")}
        return Plan(description, (request, takes, synthesis, removals, weights))

    def run(self, plan: Plan, progress: Progress) -> FolderOutput:
        request, read, synthesis, removals, weights = plan.state
        params = request.params
        removed = removed_by(read, removals, weights) if removals else read
        progress.start("evaluate takes", len(read))
        takes, per_take = [], []
        for path, perf in removed:
            takes.append((path, perf))
            per_take.append(take_diagnostics(path, perf, params["frequency"], synthesis))
            progress.advance()
        progress.finish()
        report = {"takes": [{k: v for k, v in t.items() if k != "plot"} for t in per_take]}
        if params["held_expression"]:
            report["held_expression"] = spread_diagnostics(takes, params["skip"])
        if params["session"]:
            report["session"] = session_diagnostics(read, removed, params["skip"])
        output = Path(request.output)
        output.mkdir(parents=True, exist_ok=True)
        (output / "report.json").write_text(json.dumps(report, indent=2, sort_keys=True) + "\n")
        write_plot(output / "diagnostics.png", per_take, takes, params["skip"] if params["held_expression"] else None)
        return FolderOutput({"report": str(output / "report.json"), "plot": str(output / "diagnostics.png"), **_headline(report)})

    def describe(self, report: dict) -> str:
        summary = report["summary"]
        lines = [f"report: {summary['report']}", f"plot: {summary['plot']}"]
        lines += [f"{k}: {v}" for k, v in summary.items() if k not in ("report", "plot")]
        return "\n".join(lines)


def fitting_model(path: Path, perf, kind: str):
    """The --synthesis model, checked to fit the takes (topology, frame rate) and to synthesize."""
    from facedyn.dynamics.modelfile import load_model

    model = load_model(path, topology=perf.topology, fps=perf.fps)
    if model.kind not in SYNTHESIZES:
        raise UsageError(f"--{kind} {path}: a {model.kind} model; this needs a synthesis model (H) or a linear response")
    return model


def check_response_takes(path: Path, model, takes: list) -> None:
    """A linear response is evaluated on new takes, or on its whole calibration session (each
    take removed by the response fitted without it); a part of that session is neither."""
    from facedyn.dynamics.response import calibration_names, is_linear_response
    from facedyn.processors.training_inputs import take_name

    if not is_linear_response(model):
        return
    fitted = calibration_names(model)
    given = {take_name(root): perf.frame_count for root, perf in takes}
    if set(given) & set(fitted) and (given != fitted or len(given) != len(takes)):
        raise UsageError(f"{path} was fitted on the whole takes {', '.join(sorted(fitted))}; give all of them, whole (each is then "
                         f"removed by the response fitted without it), or none of them, not {', '.join(sorted(given))}"
                         f"{' with --frames' if given.keys() == fitted.keys() else ''}")


def removed_by(read: list, models: list, weights) -> list:
    """The stabilized takes as `remove` with the models (blended by `weights`, a
    facedyn.dynamics.bands.BandWeights) would leave them: quasistatic points and the removed
    offsets; a linear response's own calibration takes are each removed by the response
    refitted without them."""
    outputs = [_removals(read, model) for model in models]
    removed = []
    for k, (path, perf) in enumerate(read):
        quasistatic, offsets = weights.combine([output[k] for output in outputs], perf.fps)
        removed.append((path, replace(perf, points=quasistatic, offsets=offsets)))
    return removed


def _removals(read: list, model) -> list:
    """[(quasistatic, offsets)] of each take removed by one model."""
    from facedyn.dynamics.response import calibration_names, is_linear_response, remove_left_out
    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.processors.training_inputs import take_name

    names = [take_name(path) for path, _ in read]
    if is_linear_response(model) and names[0] in calibration_names(model):  # its own session (check_response_takes)
        return list(remove_left_out(model, [TrainingSequence.from_performance(perf, name) for (_, perf), name in zip(read, names)]))
    from facedyn.dynamics.portable import for_take, is_portable

    # a person-independent model is set up for each take (its own rest shape and skull frame)
    return [removal_of(perf.points, *perf.skull(), perf.fps, for_take(model, perf) if is_portable(model) else model) for _, perf in read]


def check_length(path: Path, below: str, frames) -> None:
    """Refuse a selection longer than MAX_FRAMES before any frame is read (of the take below the role `below`)."""
    from facedyn.usd.frames import TakeFrames

    count = TakeFrames(path, below, frames=frames).frame_count
    if count > MAX_FRAMES:
        raise UsageError(f"{path}: {count} frames selected; evaluate reads at most {MAX_FRAMES:,} frames of a take "
                         "whole (its spectra and spreads): choose a range with --frames FIRST:LAST")


def face_vertices(perf) -> np.ndarray:
    return np.arange(perf.point_count) if perf.face_vertices is None else np.asarray(perf.face_vertices)


def landmarks_of(perf) -> np.ndarray:
    from facedyn.dynamics.samples import default_landmarks

    if perf.landmarks is not None:
        return perf.landmarks
    return default_landmarks(perf.rest_points if perf.rest_points is not None else perf.points[0])


def take_diagnostics(path: Path, perf, frequency: float | None, model) -> dict:
    """One take's numbers (rounded for the report) and its spectra (for the plot)."""
    from facedyn.dynamics import diagnostics

    fv = face_vertices(perf)
    translate, orient = perf.skull()
    captured = perf.points + perf.offsets
    spectrum = diagnostics.offset_spectrum(perf.offsets, translate, orient, landmarks_of(perf), perf.fps, fv)
    hz = frequency or spectrum["skull_peak_hz"]
    result = {
        "take": str(path), "frames": perf.frame_count, "fps": perf.fps,
        "removed_rms_mm": round(float(np.sqrt(np.mean(np.sum(perf.offsets[:, fv] ** 2, axis=-1)))) * 10, 4),
        "offsets_peak_hz": round(spectrum["offsets_peak_hz"], 2), "skull_peak_hz": round(spectrum["skull_peak_hz"], 2),
        "offsets_below_1hz_fraction": round(spectrum["offsets_below_1hz_fraction"], 4),
        "residual_frequency_hz": round(hz, 2),
        "residual_at_frequency": round(diagnostics.residual_at_frequency(perf.points, captured, perf.fps, hz, fv), 4),
        "plot": spectrum["spectra"],
    }
    if model is not None:
        from facedyn.dynamics.synthesis import synthesize_dynamics

        resynthesized, _ = synthesize_dynamics(perf.points, translate, orient, perf.fps, model)
        result["resynthesis_residual"] = round(diagnostics.resynthesis_residual(captured, resynthesized, perf.points, fv), 4)
    return result


def spread_diagnostics(takes: list, skip_s: float) -> dict:
    """The held expression's spread over the takes, after removal and as captured."""
    from facedyn.dynamics.diagnostics import held_expression_spread

    first = takes[0][1]
    fv, skip = face_vertices(first), int(round(skip_s * first.fps))
    if any(perf.frame_count <= skip for _, perf in takes):
        raise UsageError(f"--skip {skip_s:g}: leaves no frame of the shortest take")
    after = held_expression_spread([perf.points for _, perf in takes], fv, skip)
    before = held_expression_spread([perf.points + perf.offsets for _, perf in takes], fv, skip)
    return {"after_removal_mm": {k.removesuffix("_cm"): round(v * 10, 4) for k, v in after.items()},
            "captured_mm": {k.removesuffix("_cm"): round(v * 10, 4) for k, v in before.items()},
            "per_frame_ratio": round(after["per_frame_cm"] / before["per_frame_cm"], 4) if before["per_frame_cm"] > 0 else None}


def session_diagnostics(read: list, removed: list, skip_s: float) -> dict:
    """The fraction of the session's motion the removal leaves, beyond held shapes and sag
    (facedyn.processors.model_steps.session_motion_left): read, the takes as read (the
    capture is their points, plus the offsets of a removal read from their layers);
    removed, the same takes after the removal."""
    pairs = ((perf, {"removal": after.offsets}) for (_, perf), (_, after) in zip(read, removed))
    return {"motion_left_beyond_sag": session_motion_left(pairs, ("removal",), skip_s)["removal"]}


def _headline(report: dict) -> dict:
    headline = {"mean_residual_at_frequency": round(float(np.mean([t["residual_at_frequency"] for t in report["takes"]])), 4)}
    if "held_expression" in report:
        headline["held_expression_spread_ratio"] = report["held_expression"]["per_frame_ratio"]
    if "session" in report:
        headline["session_motion_left"] = report["session"]["motion_left_beyond_sag"]
    return headline


def write_plot(path: Path, per_take: list[dict], takes: list, skip_s: float | None) -> Path:
    """Spectra of each take's removed offsets beside its skull's; with a held expression, each
    take's per-frame distance from the expression's mean shape, captured and after removal."""
    from facedyn.preview.images import write_image
    from facedyn.preview.plot import Series, blank, line_chart

    panels = 2 if skip_s is None else 3
    width, height = 900, 300
    image = blank(height * panels, width)
    offsets = [Series(_label(Path(t["take"])), t["plot"]["hz"], t["plot"]["offsets"]) for t in per_take]
    skull = [Series(_label(Path(t["take"])), t["plot"]["skull_hz"], t["plot"]["skull"]) for t in per_take]
    line_chart(image, (0, 0, width, height), "removed offsets: power spectrum (normalized)", offsets, "Hz", (0.0, 20.0), log_y=True)
    line_chart(image, (0, height, width, 2 * height), "skull landmark accelerations: power spectrum (normalized)", skull, "Hz",
               (0.0, 20.0), log_y=True)
    if skip_s is not None:
        fv = face_vertices(takes[0][1])
        skip = int(round(skip_s * takes[0][1].fps))
        mean = np.concatenate([perf.points[skip:, fv] for _, perf in takes]).mean(axis=0)
        series = []
        for take_path, perf in takes:
            seconds = np.arange(skip, perf.frame_count) / perf.fps
            for label, points in (("captured", perf.points + perf.offsets), ("removed", perf.points)):
                distance = np.sqrt(np.mean(np.sum((points[skip:, fv] - mean) ** 2, axis=-1), axis=1)) * 10
                series.append(Series(f"{_label(take_path)} {label}", seconds, distance))
        line_chart(image, (0, 2 * height, width, 3 * height), "held expression: RMS distance from its mean shape (mm)", series, "s")
    return write_image(path, image)


def _label(take: Path) -> str:
    """A take's name in the plot: its folder (take roots are named take.usda)."""
    return take.parent.name or take.stem
