"""How close calibrate's chosen removal comes to the best blend of its two models, chosen with the truth.

`usdfacedyn calibrate` chooses an actor's removal without truth, on its session: the family's
F, the actor's linear response, their mean, or the two weighed per frequency band
(facedyn.dynamics.bands). This scores, on a validation actor's test takes (dialog under
walking, dialog under running, held funnel on the 8 Hz platform), each of those removals and
beside them the **truth-best band blend**: per take and per band (calibrate's bands), the
least-squares weights of F's and the response's offsets against the true dynamics. That
blend picks its weights with the take's own truth, so it is an upper bound that no
truth-free choice of weights can pass: if the chosen removal is close to it, what holds
removal back is the two models, not how calibrate weighs them.

Figures: the fraction of the true dynamics' moving part left on the face vertices
(testset.score.moving_left: each side less its mean over the take; the static share, which
no truth-free method sees, set apart), solved skull (the takes stabilized with `--actor` by
testset_score.py), plain captures with tracker noise.

    python benchmarks/testset_blend_ceiling.py --actor ACTOR_FOLDER WORK CALIBRATION [--actor ...] [--out FILE]

ACTOR_FOLDER: a validation actor (testset_generate.py); WORK: testset_score.py's --work
folder for it (its takes imported and stabilized); CALIBRATION: the actor's `usdfacedyn
calibrate` folder (family.removal, synthesis.response and the chosen removal). Validation
actors only: a test actor's truth is not used to weigh anything.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from harness import Recorder, parser
from plain_capture import usdfacedyn
from testset.score import load_truth, moving_left
from testset_ceiling import actor_name

from facedyn.dynamics.bands import EDGES_HZ, split
from facedyn.usd.take import read_layers

TAKES = ("dialog_walk", "dialog_run", "platform_8hz")
MEMBERS = {"family_F": "family.removal", "response": "synthesis.response"}


def removed_offsets(take_root: Path, model: Path, scratch: Path) -> np.ndarray:
    """(F, N, 3) what `usdfacedyn remove --model` removes from a stabilized take (its root left untouched)."""
    layer = scratch / f"{take_root.parent.name}.{model.name}.usdc"
    usdfacedyn("remove", str(take_root), "--model", str(model), "-o", str(layer))
    return np.asarray(read_layers([layer, take_root]).offsets, np.float64)


def truth_best_bands(members: list[np.ndarray], truth: dict, fps: float) -> tuple[np.ndarray, list]:
    """(the blend, its weights per band): per band, the least-squares weights of the members'
    offsets (each less its mean over the take) against the true dynamics' moving part on the
    face vertices."""
    face = truth["face_vertices"]
    moving = [m - m.mean(axis=0) for m in members]
    target = np.asarray(truth["dynamics"], np.float64)
    target = target - target.mean(axis=0)
    bands = [split(m, EDGES_HZ, fps) for m in moving]
    blend, weights = np.zeros_like(moving[0]), []
    for b, wanted in enumerate(split(target, EDGES_HZ, fps)):
        columns = np.stack([member[b][:, face].ravel() for member in bands], axis=1)
        w = np.linalg.lstsq(columns, wanted[:, face].ravel(), rcond=None)[0]
        weights.append([round(float(x), 3) for x in w])
        blend += sum(x * member[b] for x, member in zip(w, bands))
    return blend, weights


def chosen_removal(folder: Path) -> tuple[Path, str]:
    """(the removal calibrate chose in `folder`, how its models were made, from calibration.json where it has one)."""
    found = [folder / name for name in ("removal.removal", "removal.response", "removal.blend") if (folder / name).is_file()]
    if len(found) != 1:
        raise SystemExit(f"{folder}: not a calibrate folder with one chosen removal (removal.removal, .response or .blend)")
    record = folder / "calibration.json"
    if not record.is_file():
        return found[0], "usdfacedyn calibrate's models (no calibration.json beside them)"
    made = json.loads(record.read_text())
    return found[0], (f"usdfacedyn calibrate: {made['family']['epochs']} epochs of F on {made['corpus']['takes']} corpus takes, "
                      f"the response's ridge {made['response']['ridge']}, chosen {made['chosen']}")


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--actor", nargs=3, action="append", type=Path, required=True, metavar=("ACTOR", "WORK", "CALIBRATION"),
                           help="a validation actor's folder, testset_score.py's --work folder for it and its calibrate folder")
    args = arguments.parse_args()
    with Recorder("testset_blend_ceiling", args) as emit, tempfile.TemporaryDirectory(prefix="facedyn-blend-ceiling-") as scratch:
        for actor, work, folder in args.actor:
            name = actor_name(actor)
            chosen, made = chosen_removal(folder)
            for take in TAKES:
                root = work / take / "take.usda"
                if not root.is_file():
                    raise SystemExit(f"{root}: no stabilized take (run testset_score.py {actor} --work {work} first)")
                truth = load_truth(actor, take)
                members = [removed_offsets(root, folder / file, Path(scratch)) for file in MEMBERS.values()]
                blend, weights = truth_best_bands(members, truth, float(truth["fps"]))
                figures = {f"{label}_moving_left": moving_left(offsets, truth) for label, offsets in zip(MEMBERS, members)}
                figures["mean_moving_left"] = moving_left(sum(members) / 2, truth)
                figures["chosen_moving_left"] = moving_left(removed_offsets(root, chosen, Path(scratch)), truth)
                emit({"case": f"{name}: {take}", "actor": name, "take": take, "chosen": chosen.name,
                      **{key: round(value, 4) for key, value in figures.items()},
                      "truth_best_bands_moving_left_upper_bound": round(moving_left(blend, truth), 4),
                      "truth_best_band_weights": weights, "band_edges_hz": list(EDGES_HZ),
                      "obtained": {"skull": "solved (stabilize --actor, testset_score.py)", "rest": "given (the actor's rig)",
                                   "scored": "face vertices, moving part (static share set apart), usdfacedyn remove as a user runs "
                                             "it; the truth-best blend's weights chosen per take with its truth (an upper bound)",
                                   "test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset), plain captures "
                                                "with tracker noise", "split": "validation actor", "models": made}})


if __name__ == "__main__":
    main()
