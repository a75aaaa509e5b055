"""Score removals on a test-set actor's test takes (benchmarks/README-testset.md); one JSON file per run.

    .venv/bin/python benchmarks/testset_score.py ACTOR_FOLDER [--removal MODEL [--blend MODEL]] [--work DIR] [--results DIR] [--no-actor]
        [--synthesis MODEL [--transfer FOLDER]] [--note "how MODEL was made"]

Per test take: `usdfacedyn actor rig.usda`, then `import` + `stabilize --actor` of
tracked.usdc (the console as a user runs it), and the figures (fraction of the true
dynamics' RMS left, testset.score): do_nothing (1.0), moving_average (21 frames, on the
stabilized take) and, with --removal, `usdfacedyn remove --model MODEL [--blend MODEL]`.
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
`retarget_to_delta_transfer`, their ratio (issue 37: synthesis <= 0.3, the ratio <= 0.5). The run's figures, with commit, date and machine, go to RESULTS/<actor>-<UTC time>.json
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
    from testset.score import dynamics_rms_mm, fraction_left, frame_rotation, load_truth, moving_average_estimate, static_share

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("actor", type=Path, help="an actor folder written by testset_generate.py")
    parser.add_argument("--removal", type=Path, help="a removal model to score (usdfacedyn remove --model; `default`: the shipped one)")
    parser.add_argument("--no-actor", action="store_true", help="stabilize without --actor (in the take's own skull frame)")
    parser.add_argument("--blend", type=Path, help="with --removal: remove --blend (a linear response)")
    parser.add_argument("--work", type=Path, help="keep the imported takes here (default: a temporary folder)")
    parser.add_argument("--results", type=Path, default=REPO / "benchmarks" / "results" / "testset")
    parser.add_argument("--synthesis", type=Path, help="with --removal: the actor's synthesis model, scored on the transfer takes")
    parser.add_argument("--transfer", type=Path, help="the actor folder holding its transfer takes (default: ACTOR_FOLDER)")
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
    transfers = read_transfer_recipes(args.transfer or args.actor, args.actor, tests) if args.synthesis is not None else []
    run = {"actor": info["actor"]["name"], "split": info["actor"]["split"], "commit": commit(),
           "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"), "machine": platform.node(),
           "cpus": os.cpu_count(), "removal": args.removal and str(args.removal), "blend": args.blend and str(args.blend),
           "stabilized": "without --actor" if args.no_actor else "with --actor", "synthesis": args.synthesis and str(args.synthesis),
           "transfer": args.transfer and str(args.transfer),
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
                case["removal"] = round(fraction_left(read_layers([layer, folder / "take.usda"]).offsets @ turn.T, truth), 4)
            print(json.dumps(case), flush=True)
            run["takes"].append(case)
        for recipe in transfers:
            case = score_transfer(recipe, args.transfer or args.actor, work, args.synthesis)
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


def read_transfer_recipes(folder: Path, actor: Path, tests: list[str]) -> list[dict]:
    """The transfer takes' recipes in `folder` (an actor folder of the same actor as `actor`,
    both of whose sources are `tests`); exits with the reason where there are none."""
    info_path = folder / "actor.json"
    if not info_path.is_file():
        sys.exit(f"{folder}: not an actor folder (no actor.json)")
    if (folder / "rig.usda").read_bytes() != (actor / "rig.usda").read_bytes():
        sys.exit(f"{folder}: its rig.usda is not {actor}'s: the transfer takes must be the same actor's")
    recipes = [t for t in json.loads(info_path.read_text())["takes"] if t["kind"] == "transfer"]
    if not recipes:
        sys.exit(f"{folder}: has no transfer takes (generate them with --takes transfer)")
    for recipe in recipes:
        missing = [name for name in recipe["sources"] if name not in tests]
        if missing:
            sys.exit(f"{folder}: transfer take {recipe['name']} needs the test takes {missing}, which {actor} lacks")
    return recipes


def score_transfer(recipe: dict, folder: Path, work: Path, model: Path) -> dict:
    """One transfer take's synthesis, retargeting and delta transfer (the module's docstring);
    the sources' take roots in `work` hold their quasistatic layers (the removal)."""
    from facedyn.evaluation import residual_fraction
    from facedyn.usd.take import read_layers
    from testset.score import dynamics_rms_mm, fraction_left, load_truth, static_share

    expression_take, motion_take = recipe["sources"]
    truth = load_truth(folder, recipe["name"])
    target, source = work / expression_take / "take.usda", work / motion_take / "take.usda"
    out = work / recipe["name"]
    out.mkdir(exist_ok=True)
    commands = {"synthesis": ("synthesize", str(target), "--model", str(model), "--skull-motion", str(source)),
                "retarget": ("retarget", str(target), "--source", str(source), "--model", str(model)),
                "delta_transfer": ("retarget", str(target), "--source", str(source), "--method", "delta-transfer")}
    case = {"take": recipe["name"], "expression_of": expression_take, "motion_of": motion_take, "frames": len(truth["dynamics"]),
            "dynamics_rms_mm": round(dynamics_rms_mm(truth), 3), "static_share": round(static_share(truth), 4)}
    for name, command in commands.items():
        layer = out / f"{name}.usdc"
        usdfacedyn(*command, "-o", str(layer))
        reload_layers(layer, target)
        offsets = read_layers([layer, target]).offsets
        case[name] = round(fraction_left(offsets, truth), 4)
        case[f"{name}_rms_mm"] = round(residual_fraction(offsets, 0 * truth["dynamics"], truth["dynamics"], truth["face_vertices"])["residual_rms_cm"] * 10, 3)
    case["retarget_to_delta_transfer"] = round(case["retarget"] / case["delta_transfer"], 3)
    return case


if __name__ == "__main__":
    main()
