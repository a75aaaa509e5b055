"""Score removals on a test-set actor's test takes (benchmarks/README-testset.md); one JSON file per run.

    .venv/bin/python benchmarks/testset_score.py ACTOR_FOLDER [--removal MODEL [--blend MODEL]] [--work DIR] [--results DIR] [--no-actor]
        [--synthesis MODEL [--transfer FOLDER] [--source-actor FOLDER --source-removal MODEL [--source-synthesis MODEL]]]
        [--note "how MODEL was made"]

Per test take: `usdfacedyn actor rig.usda`, then `import` + `stabilize --actor` of
tracked.usdc (the console as a user runs it), and the figures (fraction of the true
dynamics' RMS left, testset.score): do_nothing (1.0), moving_average (21 frames, on the
stabilized take) and, with --removal, `usdfacedyn remove --model MODEL [--blend MODEL]`,
with `removal_moving` beside it (testset.score.moving_left: the part of the truth that moves,
each side less its mean over the take: the static share, which no truth-free method sees,
set apart; transfers get `<figure>_moving` alike).
With --no-actor the takes are stabilized without `--actor` (an actor with nothing: the
take's own skull frame, which testset.score.frame_rotation turns into the actor's to score).
MODEL may be a shipped model's name (`default`).
With --removal and --synthesis (the actor's synthesis model, e.g. calibrate's synthesis.response),
each transfer take (one test take's expression under another's skull; `testset_generate.py
--takes transfer`, in the actor folder or in --transfer FOLDER, the same actor) is scored as
the issue's synthesis and retargeting cases: the expression take's quasistatic layer (from
the removal) `synthesize`d under the motion take's solved skull (`synthesis`), `retarget`ed
from the motion take with the model (`retarget`) and by copying the motion take's removed
offsets (`delta_transfer`), each against the transfer take's true dynamics; and
`retarget_to_delta_transfer`, their ratio (issue 37: synthesis <= 0.3, the ratio <= 0.5); and
`retarget_residual` (`retarget --method residual`, the motion take's actor's synthesis model as
`--source-model`: the actor's own, or --source-synthesis for a cross take) with its ratio.
A cross take (`--takes cross --source-actor A`: the walking dialog under actor A's run) is
scored the same way across actors, the issue's retargeting case: A's run (in --source-actor
FOLDER, A's actor folder) is stabilized with A's actor and removed with A's removal
(--source-removal), and retargeting moves its root motion onto this actor (its own synthesis
model), where delta transfer copies A's tissue's offsets. The run's figures, with commit, date and machine, go to RESULTS/<actor>-<UTC time>.json
(default benchmarks/results/testset/) and to stdout, one JSON object per take.
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from plain_capture import stabilize_with_cli, usdfacedyn

REPO = Path(__file__).resolve().parents[1]


def commit() -> str:
    done = subprocess.run(["git", "-C", str(REPO), "describe", "--always", "--dirty"], capture_output=True, text=True)
    return done.stdout.strip() or "unknown"


def main() -> None:
    from facedyn.performance import QUASISTATIC
    from facedyn.usd.take import read_layers, read_take_below
    from testset.score import dynamics_rms_mm, fraction_left, frame_rotation, load_truth, moving_average_estimate, moving_left, static_share

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("actor", type=Path, help="an actor folder written by testset_generate.py")
    parser.add_argument("--removal", type=Path, help="a removal model to score (usdfacedyn remove --model; `default`: the shipped one)")
    parser.add_argument("--no-actor", action="store_true", help="stabilize without --actor (in the take's own skull frame)")
    parser.add_argument("--blend", type=Path, help="with --removal: remove --blend (a linear response)")
    parser.add_argument("--work", type=Path, help="keep the imported takes here (default: a temporary folder)")
    parser.add_argument("--results", type=Path, default=REPO / "benchmarks" / "results" / "testset")
    parser.add_argument("--synthesis", type=Path, help="with --removal: the actor's synthesis model, scored on the transfer takes")
    parser.add_argument("--transfer", type=Path, nargs="+", help="actor folders of this actor holding its transfer or cross takes "
                        "(default: ACTOR_FOLDER)")
    parser.add_argument("--source-actor", type=Path, help="with cross takes: the folder of the actor whose run they move like")
    parser.add_argument("--source-removal", type=Path, help="with --source-actor: that actor's removal model (its offsets, for delta transfer)")
    parser.add_argument("--source-synthesis", type=Path, help="with --source-actor: that actor's synthesis model (retarget --method "
                        "residual's --source-model; without it cross takes get no retarget_residual)")
    parser.add_argument("--note", default="", help="how the removal model was made (the results page shows it beside the figures)")
    args = parser.parse_args()
    info_path = args.actor / "actor.json"
    if not info_path.is_file():
        sys.exit(f"{args.actor}: not an actor folder (no actor.json); write one with benchmarks/testset_generate.py")
    info = json.loads(info_path.read_text())
    tests = [t["name"] for t in info["takes"] if t["kind"] == "test"]
    if not tests:
        sys.exit(f"{args.actor}: has no test takes (generate it with --takes test)")
    if args.synthesis is not None and (args.removal is None or args.no_actor):
        sys.exit("--synthesis needs --removal (synthesis and retargeting start from the removal's quasistatic takes) and the actor's "
                 "frame (not --no-actor)")
    transfers = ([(folder, recipe) for folder in args.transfer or [args.actor]
                  for recipe in read_transfer_recipes(folder, args.actor, tests, args.source_actor)] if args.synthesis is not None else [])
    if any(recipe["kind"] == "cross" for _, recipe in transfers) and args.source_removal is None:
        sys.exit("cross takes need --source-removal, the source actor's removal model (delta transfer copies its offsets)")
    run = {"actor": info["actor"]["name"], "split": info["actor"]["split"], "commit": commit(),
           "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"), "machine": platform.node(),
           "cpus": os.cpu_count(), "removal": args.removal and str(args.removal), "blend": args.blend and str(args.blend),
           "stabilized": "without --actor" if args.no_actor else "with --actor", "synthesis": args.synthesis and str(args.synthesis),
           "transfer": args.transfer and " ".join(map(str, args.transfer)), "source_actor": args.source_actor and str(args.source_actor),
           "source_removal": args.source_removal and str(args.source_removal),
           "source_synthesis": args.source_synthesis and str(args.source_synthesis),
           **({"note": args.note} if args.note else {}), "takes": []}
    with tempfile.TemporaryDirectory(prefix="facedyn-testset-") as scratch:
        work = args.work or Path(scratch)
        work.mkdir(parents=True, exist_ok=True)
        actor = work / "actor.usda"
        if not actor.is_file():
            usdfacedyn("actor", str(args.actor / "rig.usda"), "-o", str(actor))
        for name in tests:
            truth = load_truth(args.actor, name)
            folder = work / (f"{name}_no_actor" if args.no_actor else name)
            if not (folder / "take.usda").is_file():
                folder.mkdir(parents=True, exist_ok=True)
                stabilize_with_cli(args.actor / "takes" / name / "tracked.usdc", folder, None if args.no_actor else actor)
            reload_layers(folder / "take.usda", folder / "quasistatic.usdc")
            stabilized, _ = read_take_below(folder / "take.usda", QUASISTATIC)  # a rerun in --work finds the removal attached
            turn = frame_rotation(stabilized.points, truth) if args.no_actor else np.eye(3)  # estimates into the actor's frame
            case = {"take": name, "frames": len(truth["dynamics"]), "dynamics_rms_mm": round(dynamics_rms_mm(truth), 3),
                    "static_share": round(static_share(truth), 4), "do_nothing": 1.0,
                    "moving_average": round(fraction_left(moving_average_estimate(stabilized.points, truth) @ turn.T, truth), 4)}
            if args.removal is not None:
                layer = folder / "quasistatic.usdc"
                usdfacedyn("remove", str(folder / "take.usda"), "-o", str(layer), "--attach", str(folder / "take.usda"),
                           "--model", str(args.removal), *(("--blend", str(args.blend)) if args.blend else ()))
                reload_layers(layer, folder / "take.usda")
                removed = read_layers([layer, folder / "take.usda"]).offsets @ turn.T
                case["removal"] = round(fraction_left(removed, truth), 4)
                case["removal_moving"] = round(moving_left(removed, truth), 4)
            print(json.dumps(case), flush=True)
            run["takes"].append(case)
        for folder, recipe in transfers:
            expression_take, motion_take = recipe["sources"]
            source = (work / motion_take / "take.usda" if recipe["kind"] == "transfer"
                      else source_take(args.source_actor, motion_take.split("/")[1], work / "source", args.source_removal))
            source_model = args.synthesis if recipe["kind"] == "transfer" else args.source_synthesis
            case = score_transfer(recipe, folder, work / expression_take / "take.usda", source, work, args.synthesis, source_model)
            print(json.dumps(case), flush=True)
            run.setdefault("transfers", []).append(case)
    dialogs = [c for c in run["takes"] if c["take"].startswith("dialog")]
    if dialogs:
        run["dialogs_mean"] = {key: round(sum(c[key] for c in dialogs) / len(dialogs), 4) for key in dialogs[0] if key not in ("take", "frames")}
    args.results.mkdir(parents=True, exist_ok=True)
    path = args.results / f"{run['actor']}-{run['date'].replace(':', '').replace('+0000', 'Z')}.json"
    path.write_text(json.dumps(run, indent=1) + "\n")
    print(json.dumps({"written": str(path)}))


def reload_layers(*paths: Path) -> None:
    """Read again the layers this process has open that a command (another process) may have
    rewritten since: USD keeps an opened layer for the process's life, and a rerun in --work
    rewrites the removal and the take's root."""
    from pxr import Sdf

    for path in paths:
        layer = Sdf.Layer.Find(str(path))
        if layer is not None:
            layer.Reload(force=True)


def read_transfer_recipes(folder: Path, actor: Path, tests: list[str], source_actor: Path | None) -> list[dict]:
    """The transfer and cross takes' recipes in `folder` (an actor folder of the same actor as
    `actor`; a transfer's sources are `tests`, a cross take's expression is one of `tests` and its
    motion a test take of `source_actor`); exits with the reason where there are none."""
    info_path = folder / "actor.json"
    if not info_path.is_file():
        sys.exit(f"{folder}: not an actor folder (no actor.json)")
    if (folder / "rig.usda").read_bytes() != (actor / "rig.usda").read_bytes():
        sys.exit(f"{folder}: its rig.usda is not {actor}'s: the transfer takes must be the same actor's")
    recipes = [t for t in json.loads(info_path.read_text())["takes"] if t["kind"] in ("transfer", "cross")]
    if not recipes:
        sys.exit(f"{folder}: has no transfer takes (generate them with --takes transfer or cross)")
    for recipe in recipes:
        expression_take, motion_take = recipe["sources"]
        needed = (expression_take, motion_take) if recipe["kind"] == "transfer" else (expression_take,)  # a cross take's motion is another actor's
        missing = [name for name in needed if name not in tests]
        if missing:
            sys.exit(f"{folder}: transfer take {recipe['name']} needs the test takes {missing}, which {actor} lacks")
        if recipe["kind"] == "cross":
            name, take = motion_take.split("/")
            if source_actor is None or not (source_actor / "actor.json").is_file():
                sys.exit(f"{folder}: cross take {recipe['name']} moves like {motion_take}: give --source-actor, {name}'s actor folder")
            if json.loads((source_actor / "actor.json").read_text())["actor"]["name"] != name or not (source_actor / "takes" / take).is_dir():
                sys.exit(f"{source_actor}: is not the actor folder of {name} with its take {take}")
    return recipes


def source_take(source_actor: Path, take: str, work: Path, removal: Path) -> Path:
    """A cross take's motion take, as the source actor's own pipeline leaves it: imported,
    stabilized with its actor, its dynamics removed with its removal (attached to its root)."""
    folder = work / take
    actor = work / "actor.usda"
    if not actor.is_file():
        work.mkdir(parents=True, exist_ok=True)
        usdfacedyn("actor", str(source_actor / "rig.usda"), "-o", str(actor))
    if not (folder / "take.usda").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        stabilize_with_cli(source_actor / "takes" / take / "tracked.usdc", folder, actor)
    usdfacedyn("remove", str(folder / "take.usda"), "-o", str(folder / "quasistatic.usdc"), "--attach", str(folder / "take.usda"),
               "--model", str(removal))
    reload_layers(folder / "quasistatic.usdc", folder / "take.usda")
    return folder / "take.usda"


def score_transfer(recipe: dict, folder: Path, target: Path, source: Path, work: Path, model: Path, source_model: Path | None) -> dict:
    """One transfer take's synthesis, retargeting and delta transfer (the module's docstring);
    target, source: the expression's and the motion's take roots, holding their quasistatic
    layers (the removal); the layers made go to `work`/<take>. With source_model (the motion
    take's actor's synthesis model), also `retarget --method residual` (retarget_residual)."""
    from facedyn.evaluation import residual_fraction
    from facedyn.usd.take import read_layers
    from testset.score import dynamics_rms_mm, fraction_left, load_truth, moving_left, static_share

    expression_take, motion_take = recipe["sources"]
    truth = load_truth(folder, recipe["name"])
    out = work / recipe["name"]
    out.mkdir(exist_ok=True)
    commands = {"synthesis": ("synthesize", str(target), "--model", str(model), "--skull-motion", str(source)),
                "retarget": ("retarget", str(target), "--source", str(source), "--model", str(model)),
                "delta_transfer": ("retarget", str(target), "--source", str(source), "--method", "delta-transfer")}
    if source_model is not None:
        commands["retarget_residual"] = ("retarget", str(target), "--source", str(source), "--model", str(model), "--method", "residual",
                                         "--source-model", str(source_model))
    case = {"take": recipe["name"], "expression_of": expression_take, "motion_of": motion_take, "frames": len(truth["dynamics"]),
            "dynamics_rms_mm": round(dynamics_rms_mm(truth), 3), "static_share": round(static_share(truth), 4)}
    for name, command in commands.items():
        layer = out / f"{name}.usdc"
        usdfacedyn(*command, "-o", str(layer))
        reload_layers(layer, target)
        offsets = read_layers([layer, target]).offsets
        case[name] = round(fraction_left(offsets, truth), 4)
        case[f"{name}_moving"] = round(moving_left(offsets, truth), 4)
        case[f"{name}_rms_mm"] = round(residual_fraction(offsets, 0 * truth["dynamics"], truth["dynamics"], truth["face_vertices"])["residual_rms_cm"] * 10, 3)
    case["retarget_to_delta_transfer"] = round(case["retarget"] / case["delta_transfer"], 3)
    if "retarget_residual" in case:
        case["retarget_residual_to_delta_transfer"] = round(case["retarget_residual"] / case["delta_transfer"], 3)
    return case


if __name__ == "__main__":
    main()
