"""What any model fitted on an actor's calibration session can reach on the test takes, given the session's truth.

`usdfacedyn calibrate` fits the actor's linear response on its session's captures, without
truth. testset_ceiling.py showed that the same response fitted on the session's *true*
dynamics does no better on the run, and testset_blend_ceiling.py that calibrate's choice
between its two models is close to the best blend of them. This asks the next question: is
the response's form what holds it back, or what a session can teach? Each model below is
fitted on the session's true dynamics (no expression, no tracker noise, true skull: what a
truth-free fit can at best hope for) and scored on the validation actor's three test takes:

- ``response``: facedyn.dynamics.response.fit_linear_response as calibrate runs it (modal
  form, ridge chosen by the session, stiffening);
- ``linear FIR, past P``: an unconstrained linear filter from the five landmarks'
  accelerations over frames t-P..t+10 to the samples' offsets, its ridge chosen by five
  folds of the session's takes (`RIDGES`);
- ``MLP``: a network (two hidden layers of 256, GELU) beside that filter, on the same window,
  stopped where every tenth session take, held out, is best: the nonlinear answer the session
  could teach.

Two probes re-simulate the walking dialog on the actor's MuJoCo tissue and score the response
on them: the same walk with a neutral face (does the dialog's changing expression limit it?)
and at half the motion (does the tissue's nonlinearity?). Figures: the fraction of the true
dynamics' moving part left (each side less its mean over the take) at the models' sample
vertices (F_SAMPLES of the face), true skull; ``session_left``: the same over the session's
own takes, in sample; for the 0.5 s filter also each take fitted without it, and each held
expression's takes fitted without them (does the tissue answer each expression differently?).

    python benchmarks/testset_session_ceiling.py ACTOR_FOLDER [--session FOLDER] [--out benchmarks/results/testset_session_ceiling.json]

Validation actors only (README-testset.md): a test actor's tissue is not probed.
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from harness import Recorder
from testset.actors import FPS, SUBSTEPS, test_takes
from testset.generate import simulate_take
from testset.score import load_truth
from testset.takes import HELD
from testset.tissue import MujocoTissue, TissueParams
from testset_ceiling import DATA, as_take, session_truths, synthesized, validation_actor

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.response import SETTLE_S, fit_linear_response, response_template
from facedyn.dynamics.skull_motion import SkullMotionInput

TAKES = ("dialog_walk", "dialog_run", "platform_8hz")
RIDGES = (1e-3, 1e-2, 1e-1)  # per row, on standardized features
FOLDS = 5
PASTS = (30, 90)  # frames of skull history the filters read (calibrate's response reads 30)
NEUTRAL = "neutral (probe)"  # a held expression of no shapes: the face at rest


def moving_left_at(estimate: np.ndarray, truth: np.ndarray) -> float:
    """Moving part left: RMS of (estimate - truth), each less its mean over the take, / RMS of the truth less its mean."""
    residual = estimate - truth
    residual = residual - residual.mean(axis=0)
    moving = truth - truth.mean(axis=0)
    return float(np.sqrt(np.sum(residual ** 2) / np.sum(moving ** 2)))


class Window:
    """A take's skull window (landmark accelerations over t-past..t+10) and its true offsets at the samples."""

    def __init__(self, face: FaceSetup, past: int):
        self.motion, self.face = SkullMotionInput("acceleration", past, 10), face

    def rows(self, truth: dict) -> tuple[np.ndarray, np.ndarray]:
        x = self.motion.features(truth["skull_translate"], truth["skull_orient"], self.face.landmarks, float(truth["fps"]))
        y = np.asarray(truth["dynamics"], np.float64)[:, self.face.samples].reshape(len(x), -1)
        return x.astype(np.float64), y


def settled_centred(x: np.ndarray, y: np.ndarray, settle: int) -> tuple[np.ndarray, np.ndarray]:
    """The take's rows after it settles, each side less its mean there (a per-take intercept)."""
    x, y = x[settle:], y[settle:]
    return x - x.mean(axis=0), y - y.mean(axis=0)


class FilterSums:
    """A session's sums for a ridge regression on standardized features, per take (its Gram, moments
    and rows), so that the fit without any group of takes subtracts that group's sums from the
    session's instead of summing the others again."""

    def __init__(self, session: list[tuple[np.ndarray, np.ndarray]]):
        self.session = session
        self.scale = np.concatenate([x for x, _ in session]).std(axis=0) + 1e-12
        self.takes = [((x / self.scale).T @ (x / self.scale), (x / self.scale).T @ y, len(x)) for x, y in session]
        self.total = [sum(t[k] for t in self.takes) for k in range(3)]

    def solve(self, ridge: float, without: tuple[int, ...] = ()) -> np.ndarray:
        gram, moment, count = (self.total[k] - sum(self.takes[i][k] for i in without) for k in range(3))
        return np.linalg.solve(gram + ridge * count * np.eye(len(gram)), moment)

    def held_out_left(self, groups: list, ridge: float) -> float:
        """The moving part the filter leaves of each group's takes, fitted without that group (a
        group of one take each, every FOLDS-th take, or each held expression's)."""
        err = energy = 0.0
        for group in sorted(set(groups)):
            members = tuple(i for i, g in enumerate(groups) if g == group)
            weights = self.solve(ridge, members)
            for i in members:
                x, y = self.session[i]
                err += float(np.sum(((x / self.scale) @ weights - y) ** 2))
                energy += float(np.sum(y ** 2))
        return float(np.sqrt(err / energy))

    def fit(self) -> tuple[np.ndarray, float]:
        """(weights, ridge): the ridge that leaves the least of `FOLDS` folds of takes, each fitted without it."""
        folds = [i % FOLDS for i in range(len(self.session))]
        ridge = min(RIDGES, key=lambda r: self.held_out_left(folds, r))
        return self.solve(ridge), ridge


def held_expression(take: str) -> str:
    """A session take's held expression: session_<expression>_<motion> (testset.actors' names)."""
    parts = take.removeprefix("session_").rsplit("_", 2)
    return parts[0] if parts[-2] == "131" else take.removeprefix("session_").rsplit("_", 1)[0]


def fit_mlp(session: list[tuple[np.ndarray, np.ndarray]], linear: np.ndarray, scale: np.ndarray, *, hidden: int = 256,
            epochs: int = 60, seed: int = 0):
    """A network beside the fitted filter (its output added to the filter's), trained on every take
    but every tenth and kept at the epoch where those held-out takes are best; returns a function
    of the window rows."""
    import torch

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    held = np.concatenate([np.full(len(x), i % 10 == 0) for i, (x, _) in enumerate(session)])
    x = torch.tensor(np.concatenate([x for x, _ in session]) / scale, dtype=torch.float32)
    y = torch.tensor(np.concatenate([y for _, y in session]), dtype=torch.float32)
    spread = y.std(dim=0) + 1e-9
    base = torch.tensor(linear, dtype=torch.float32)
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], hidden), torch.nn.GELU(), torch.nn.Linear(hidden, hidden), torch.nn.GELU(),
                              torch.nn.Linear(hidden, y.shape[1]))
    torch.nn.init.zeros_(net[-1].weight)
    torch.nn.init.zeros_(net[-1].bias)
    optimizer = torch.optim.AdamW(net.parameters(), lr=1e-3, weight_decay=1e-4)

    def predict(rows):
        return rows @ base + net(rows) * spread

    train, test = np.flatnonzero(~held), np.flatnonzero(held)
    best = (np.inf, None, -1)
    for epoch in range(epochs):
        order = rng.permutation(train)
        for start in range(0, len(order), 256):
            batch = order[start:start + 256]
            loss = (((predict(x[batch]) - y[batch]) / spread) ** 2).mean()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
        with torch.no_grad():
            held_loss = float((((predict(x[test]) - y[test]) / spread) ** 2).mean())
        if held_loss < best[0]:
            best = (held_loss, {k: v.clone() for k, v in net.state_dict().items()}, epoch)
    net.load_state_dict(best[1])

    def run(rows: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return predict(torch.tensor(rows / scale, dtype=torch.float32)).numpy().astype(np.float64)
    return run, best[2] + 1


def main() -> None:
    args, name, spec, rig, face = validation_actor(__doc__)
    samples = face.samples
    session = session_truths(args.session or args.actor)
    tests = {take: load_truth(args.actor, take) for take in TAKES}
    neutral = np.asarray(rig.neutral, np.float64)
    settle = int(round(SETTLE_S * FPS))
    obtained = {"skull": "true", "rest": "given (the actor's rig)", "fitted on": "the session's true dynamics (70 takes)",
                "scored": "each test take's moving part (static share set apart), at the models' sample vertices",
                "test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset), true dynamics",
                "split": "validation actor"}

    def at_samples(truth: dict) -> np.ndarray:
        return np.asarray(truth["dynamics"], np.float64)[:, samples].reshape(len(truth["dynamics"]), -1)

    with Recorder("testset_session_ceiling", args) as emit:
        def record(label: str, predict, seconds: float, **extra) -> None:
            figures = {take: round(moving_left_at(predict(truth), at_samples(truth)), 4) for take, truth in tests.items()}
            in_sample = [moving_left_at(predict(truth)[settle:], at_samples(truth)[settle:]) for _, truth in session]
            emit({"case": f"{name}: {label}", "actor": name, "model": label, **figures,
                  "session_left": round(float(np.sqrt(np.mean(np.square(in_sample)))), 4), **extra,
                  "fit_seconds": round(seconds, 1), "obtained": obtained})

        began = time.perf_counter()
        response = fit_linear_response(response_template(face, FPS), [as_take(k, t, neutral + t["dynamics"]) for k, t in session])
        seconds = time.perf_counter() - began

        def respond(truth: dict) -> np.ndarray:
            return synthesized(response, truth)[:, samples].reshape(len(truth["dynamics"]), -1)
        calibration = response.info["calibration"]
        record("response (calibrate's form)", respond, seconds, ridge=calibration["ridge"], hardening=round(calibration["hardening"], 3))

        for past in PASTS:
            window = Window(face, past)
            began = time.perf_counter()
            rows = [settled_centred(*window.rows(truth), settle) for _, truth in session]
            sums = FilterSums(rows)
            (weights, ridge), scale = sums.fit(), sums.scale
            seconds = time.perf_counter() - began
            extra = {}
            if past == PASTS[0]:
                names = [take for take, _ in session]
                extra = {"session_left_each_take_held_out": round(sums.held_out_left(names, ridge), 4),
                         "session_left_each_expression_held_out": round(sums.held_out_left([held_expression(t) for t in names], ridge), 4),
                         "held_expressions": len({held_expression(t) for t in names})}
            record(f"linear FIR, past {past}", lambda truth: (window.rows(truth)[0] / scale) @ weights, seconds, ridge=ridge, **extra)
            if past == PASTS[0]:
                began = time.perf_counter()
                network, epochs = fit_mlp(rows, weights, scale)
                record(f"MLP beside the FIR, past {past}", lambda truth: network(window.rows(truth)[0]), time.perf_counter() - began,
                       epochs_kept=epochs)

        tissue = MujocoTissue(rig.neutral, rig.topology.triangles(), rig.face_vertices, TissueParams.random(spec.tissue_seed),
                              1.0 / (FPS * SUBSTEPS[spec.face]))
        walk, _, _ = test_takes(spec.take_seed)
        HELD.setdefault(NEUTRAL, {})
        for label, recipe in (("walk, neutral face", replace(walk, dialog=None, expression=NEUTRAL)),
                              ("walk, half the motion", replace(walk, motion_scale=0.5))):
            began = time.perf_counter()
            truth = simulate_take(rig, tissue, recipe, DATA)
            emit({"case": f"{name}: response (calibrate's form) on the {label}", "actor": name, "model": "response (calibrate's form)",
                  "probe": label, "probe_left": round(moving_left_at(respond(truth), at_samples(truth)), 4),
                  "dialog_walk": round(moving_left_at(respond(tests["dialog_walk"]), at_samples(tests["dialog_walk"])), 4),
                  "probe_dynamics_rms_mm": round(float(np.sqrt(np.square(at_samples(truth)).reshape(len(truth["dynamics"]), -1, 3)
                                                               .sum(-1).mean())) * 10, 3),
                  "simulation_seconds": round(time.perf_counter() - began, 1), "obtained": obtained})


if __name__ == "__main__":
    main()
