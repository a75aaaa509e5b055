"""Where the skull's acceleration power lies: procedural gaits, with and without jolts, beside real mocap.

Soft tissue on the face resonates at 5-15 Hz (facedyn.sim.tissue's springs at 5-9 Hz and
faster where the tissue thins; the volumetric layer's local frequencies 8-40 Hz), so a
motion source that has no acceleration there never makes the tissue ring. For each source
this prints one JSON object: the fraction of the skull origin's linear acceleration power
and of the angular acceleration power (skull axes, all three axes together, mean removed)
between 6 and 15 Hz, and the RMS of each. Sources: every procedural gait of facedyn.motion
(walk, run, hop, dance, turn, jump) smooth and with foot-contact jolts (``impacts=True``),
averaged over seeds, and the CMU clips in ../shared/data when it is there (whole clips,
resampled to 120 fps as `simulate` reads them).

    python benchmarks/bench_motion_spectrum.py [--seconds 6] [--seeds 4] [--out benchmarks/results/motion_spectrum.json]
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn import motion
from harness import Recorder, parser

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
FPS = 120.0
BAND_HZ = (6.0, 15.0)
GAITS = ("walk", "run", "hop", "dance", "turn", "jump")


def band_fraction(values: np.ndarray, fps: float) -> float:
    """Fraction of the power of (F, 3) values between BAND_HZ, over all axes."""
    power = np.abs(np.fft.rfft(values - values.mean(axis=0), axis=0)) ** 2
    freqs = np.fft.rfftfreq(len(values), 1.0 / fps)
    band = (freqs >= BAND_HZ[0]) & (freqs <= BAND_HZ[1])
    return float(power[band].sum() / max(power.sum(), 1e-30))


def describe(trajectory: motion.SkullTrajectory) -> dict:
    kinematics = motion.accelerations(trajectory)
    linear, angular = kinematics.linear_acceleration_skull[2:-2], kinematics.angular_acceleration_skull[2:-2]  # ends repeat neighbours
    return {"linear_in_band": band_fraction(linear, trajectory.fps), "angular_in_band": band_fraction(angular, trajectory.fps),
            "linear_rms_g": float(np.sqrt(np.mean(np.sum(linear**2, axis=1)))) / motion.G_CM_S2,
            "angular_rms_rad_s2": float(np.sqrt(np.mean(np.sum(angular**2, axis=1))))}


def summary(source: str, rows: list[dict], **extra) -> dict:
    mean = {key: round(float(np.mean([r[key] for r in rows])), 3) for key in rows[0]}
    return {"case": source, "band_hz": list(BAND_HZ), **mean, **extra}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--seconds", type=float, default=6.0, help="length of each procedural take")
    arguments.add_argument("--seeds", type=int, default=4, help="procedural takes per source (the mean is printed)")
    args = arguments.parse_args()
    with Recorder("bench_motion_spectrum", args) as emit:
        for kind in GAITS:
            for impacts in (False, True):
                rows = [describe(getattr(motion, kind)(args.seconds, FPS, seed, impacts=impacts)) for seed in range(args.seeds)]
                emit(summary(f"{kind}{' + impacts' if impacts else ''}", rows, seeds=args.seeds, seconds=args.seconds))
        for clip in sorted((DATA / "cmu-mocap").glob("*.bvh")) if DATA.is_dir() else []:
            emit(summary(f"CMU {clip.stem}", [describe(motion.from_bvh(clip, fps=FPS))], seconds="whole clip"))


if __name__ == "__main__":
    main()
