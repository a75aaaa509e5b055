"""The test set's static offsets: how the part of the true dynamics that does not move grows with the motion.

A truth-free removal or synthesis sees a take's mean offset only as part of the expression, so
the static share (benchmarks/testset/score.py) is a floor under its figure on that take. This
measures where the share comes from on the validation actors' MuJoCo tissues
(benchmarks/README-testset.md), re-simulating two test recipes (1.5 s each, the lead-in
before): the held funnel on the 8 Hz platform at several amplitudes (the test's is
facedyn.motion.PLATFORM_AMPLITUDE_CM), once more at twice the time steps per frame (physics or
integration?), and the run (CMU 131_02 at 1.6x) with its skull motion scaled about its steady
path (testset.takes.scaled_about_steady_path). A linear tissue's mean offset would stay zero;
a weakly nonlinear one's grows with the square of the motion; one that settles into another
equilibrium jumps. One JSON record per case: the mean offset's RMS and largest vertex, the
moving part's RMS (mm) and the static share. The run's cases also say how the moving part
itself departs from a linear tissue's: its RMS per unit of motion scale, and how far it is
from the quarter-size run's scaled up to its size (0 for a linear tissue), overall and per
frequency band: what a linear response fitted at a quarter of the run's motion would miss
even fitted perfectly.

    python benchmarks/testset_static.py [--actors val_default_2101 val_default_2112] [--jobs 2] [--out benchmarks/results/testset_static.json]

Validation actors only: a test actor's tissue is not to be probed (README-testset.md).
"""
from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

from harness import Recorder, parser
from testset.actors import ACTORS, FPS, SUBSTEPS, test_takes
from testset.generate import actor_rig, simulate_take
from testset.score import static_share
from testset.takes import TakeRecipe
from testset.tissue import MujocoTissue, TissueParams

from facedyn import motion

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SECONDS = 1.5
PLATFORM_SCALES = (0.5, 0.75, 1.0)
RUN_SCALES = (0.25, 0.5, 1.0, 1.3)
REFERENCE_SCALE = 0.25  # the run nearest a linear tissue
BANDS_HZ = (2.0, 4.0, 8.0, 15.0)  # edges of the bands the departure is split into


def cases(actor: str) -> list[tuple[str, TakeRecipe, int, bool]]:
    """(label, recipe, substeps, whether it is the run): the platform's amplitudes, its time-step check, the run's sizes."""
    spec = ACTORS[actor]
    _, run, platform = (replace(recipe, duration_s=SECONDS) for recipe in test_takes(spec.take_seed))
    steps = SUBSTEPS[spec.face]
    amplitude = motion.PLATFORM_AMPLITUDE_CM
    rows = [(f"8 Hz platform, {scale * amplitude:g} cm", replace(platform, motion_scale=scale), steps, False) for scale in PLATFORM_SCALES]
    rows.append((f"8 Hz platform, {amplitude:g} cm, {2 * steps} steps a frame", platform, 2 * steps, False))
    rows += [(f"run (131_02 at 1.6x), motion x{scale:g}", replace(run, motion_scale=scale), steps, True) for scale in RUN_SCALES]
    return rows


def measure(actor: str, label: str, recipe: TakeRecipe, substeps: int) -> tuple[dict, np.ndarray]:
    """Simulate one case on the actor's own rig and tissue: (its record: the offsets' mean and
    moving part; the moving part (F, V, 3) in mm)."""
    spec = ACTORS[actor]
    rig = actor_rig(spec, DATA)
    tissue = MujocoTissue(rig.neutral, rig.topology.triangles(), rig.face_vertices, TissueParams.random(spec.tissue_seed),
                          1.0 / (FPS * substeps))
    start = time.perf_counter()
    take = simulate_take(rig, tissue, recipe, DATA)
    dynamics = np.asarray(take["dynamics"], np.float64)[:, take["face_vertices"]] * 10.0  # mm
    mean = dynamics.mean(axis=0)
    return {"case": label, "actor": actor, "motion": recipe.motion, "motion_scale": recipe.motion_scale, "substeps": substeps,
            "seconds_simulated": SECONDS, "static_rms_mm": round(float(np.sqrt((mean ** 2).sum(-1).mean())), 4),
            "static_max_mm": round(float(np.linalg.norm(mean, axis=-1).max()), 3),
            "moving_rms_mm": round(float(np.sqrt(((dynamics - mean) ** 2).sum(-1).mean())), 4),
            "static_share": round(static_share(take), 4), "cpu_seconds": round(time.perf_counter() - start, 1),
            "obtained": {"test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset), true dynamics",
                         "split": "validation actor"}}, dynamics - mean


def departure_from_linear(moving: np.ndarray, scale: float, reference: np.ndarray, fps: float) -> dict:
    """How far a run's moving part (mm) is from the reference run's scaled up to its motion
    scale, as a fraction of its RMS: overall, and in each frequency band (the bands' squares
    add up to the overall one's: an exact split of the difference's energy, which overlapping
    filters such as calibrate's band split would not give)."""
    difference = moving - reference * (scale / REFERENCE_SCALE)
    size = np.sqrt(np.sum(moving ** 2))
    energy = (np.abs(np.fft.rfft(difference, axis=0)) ** 2).reshape(len(difference) // 2 + 1, -1).sum(axis=1)
    once = [0] + ([len(energy) - 1] if len(difference) % 2 == 0 else [])  # the bins with no mirror image
    energy = np.where(np.isin(np.arange(len(energy)), once), 1.0, 2.0) * energy / len(difference)  # Parseval
    hz = np.fft.rfftfreq(len(difference), 1.0 / fps)
    edges = (0.0, *BANDS_HZ, np.inf)
    return {"moving_rms_per_unit_motion_mm": round(float(np.sqrt((moving ** 2).sum(-1).mean())) / scale, 4),
            "departure_from_quarter_size_scaled_up": round(float(np.sqrt(np.sum(difference ** 2)) / size), 4),
            "departure_by_band": {f"{lo:g}-{hi:g} Hz": round(float(np.sqrt(energy[(hz >= lo) & (hz < hi)].sum()) / size), 4)
                                  for lo, hi in zip(edges[:-1], edges[1:])}}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--actors", nargs="+", default=["val_default_2101", "val_default_2112"],
                           choices=sorted(a for a, s in ACTORS.items() if s.split == "validation"))
    arguments.add_argument("--jobs", type=int, default=2, help="cases simulated at a time, one core each")
    args = arguments.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA}: the shared data folder is needed (its CMU mocap and Live Link curves)")
    jobs = [(actor, *case) for actor in args.actors for case in cases(actor)]
    with Recorder("testset_static", args) as emit, ProcessPoolExecutor(max(args.jobs, 1)) as pool:
        results = list(pool.map(measure, *zip(*[job[:4] for job in jobs])))
        references = {actor: moving for (actor, _, recipe, _, is_run), (_, moving) in zip(jobs, results)
                      if is_run and recipe.motion_scale == REFERENCE_SCALE}
        for (actor, _, recipe, _, is_run), (record, moving) in zip(jobs, results):
            if is_run:
                record.update(departure_from_linear(moving, recipe.motion_scale, references[actor], FPS))
            emit(record)


if __name__ == "__main__":
    main()
