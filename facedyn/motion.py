"""Skull motion sources: procedural gaits, a vibrating platform, stillness and mocap.

Synthesis, retargeting and the soft-tissue simulator need skull trajectories with realistic accelerations, because
they are what make a face jiggle. Every source returns a `SkullTrajectory`
(``world = R(orient) @ skull + translate``, cm, Y up, the skull facing +Z at the identity
like the face rig), sampled at ``fps`` from time 0, ``round(duration_s * fps)`` frames.

The gaits start at the origin and advance along +Z. Their magnitudes follow gait studies of
the head: walking at ~2 steps/s bobs ~4 cm with vertical acceleration peaks of ~0.4 g;
running at ~2.8 steps/s has a flight phase (free fall, -1 g) and ~1 g stance peaks;
hopping at ~2 hops/s has ~1.3 g landing peaks. On top of the gait's small rhythmic sway the
head looks around: turns of up to `look_deg` in yaw (a quarter of it in pitch) with
minimum-jerk profiles, about one a second, never faster than LOOK_MAX_DEG_S, as real
mocap of walking and hopping shows (CMU subject 131: 95th percentile 100-300 deg/s, peaks
~400 deg/s); the rotational loads they cause are a large part of real secondary dynamics.
Each take draws its amplitudes, phases, turns and a slow tempo drift from ``seed``, so
takes differ but repeat exactly. With ``impacts=True`` every foot contact also jolts the
head: a short transient ringing at 6-16 Hz (`_contact_transients`), as real gaits do.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from os import PathLike

import numpy as np

from facedyn.geometry import quaternion
from facedyn.io.bvh import head_trajectory
from facedyn.io.resample import bracket, time_grid
from facedyn.performance import SkullTrajectory

G_CM_S2 = 980.665
"""Standard gravity in cm/s^2."""

PLATFORM_AMPLITUDE_CM = 0.15
"""The vibrating platform's amplitude: 0.73 g at 11 Hz, about 5 mm peak offsets, as in the paper."""

PLATFORM_AXES = {"side": 0, "up": 1, "forward": 2}
"""The axes a platform can shake along (x, y, z of the world: y up, the actor facing +z)."""


@dataclass(frozen=True)
class Ramp:
    """How a motion starts and stops: still for `before_s`, fades in over `in_s`, moves,
    fades out over `out_s`, then still for `after_s` (e.g. to watch offsets decay)."""

    in_s: float = 0.0
    out_s: float = 0.0
    before_s: float = 0.0
    after_s: float = 0.0

    def envelope(self, times: np.ndarray, duration_s: float) -> np.ndarray:
        """Amplitude 0..1 per time; quintic fades keep accelerations continuous."""
        parts = (self.in_s, self.out_s, self.before_s, self.after_s)
        if min(parts) < 0:
            raise ValueError(f"ramp durations must be >= 0, got {self}")
        if sum(parts) > duration_s + 1e-9:
            raise ValueError(f"ramp takes {sum(parts)} s, longer than the {duration_s} s motion")
        rise = _fade(times - self.before_s, self.in_s)
        fall = _fade(duration_s - self.after_s - times, self.out_s)
        return rise * fall


def _fade(x: np.ndarray, width: float) -> np.ndarray:
    """0 for x <= 0, 1 for x >= width, C2 smoothstep between (a step when width is 0)."""
    if width == 0:
        return (x >= 0).astype(np.float64)
    u = np.clip(x / width, 0.0, 1.0)
    return u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)


@dataclass(frozen=True)
class _Gait:
    """One gait's nominal head motion; amplitudes are per-component peaks."""

    step_hz: float
    speed_cm_s: float
    flight: float  # fraction of each step in the air (free fall); 0 walks with a sinusoidal bob
    bob_cm: float  # vertical bob when walking (flight gaits follow ballistics instead)
    surge_cm: float  # forward oscillation at the step rate
    sway_cm: float  # lateral oscillation at the stride rate (half the step rate)
    pitch_deg: float  # nodding at the step rate
    yaw_deg: float  # at the stride rate
    roll_deg: float  # at the stride rate
    look_deg: float  # largest head turn to either side (yaw; pitch turns are a quarter of it)
    impact_g: float = 0.0  # peak head acceleration of each foot contact's transient (`impacts`)


_WALK = _Gait(step_hz=2.0, speed_cm_s=130.0, flight=0.0, bob_cm=2.0, surge_cm=0.8, sway_cm=2.0, pitch_deg=2.0, yaw_deg=2.0, roll_deg=1.5, look_deg=60.0, impact_g=0.5)
_RUN = _Gait(step_hz=2.8, speed_cm_s=300.0, flight=0.4, bob_cm=0.0, surge_cm=1.0, sway_cm=1.5, pitch_deg=3.0, yaw_deg=3.0, roll_deg=2.0, look_deg=30.0, impact_g=1.5)
_HOP = _Gait(step_hz=2.0, speed_cm_s=40.0, flight=0.46, bob_cm=0.0, surge_cm=1.0, sway_cm=0.5, pitch_deg=4.0, yaw_deg=1.0, roll_deg=1.0, look_deg=90.0, impact_g=1.5)
LOOK_MAX_DEG_S = 400.0
"""The fastest head turn the gaits make (peak angular speed of one turn)."""


def walk(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, step_hz: float = 2.0,
         speed_cm_s: float = 130.0, look_deg: float = _WALK.look_deg, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Walking: ~2 steps/s, ~4 cm bob, vertical acceleration peaks ~0.4 g, looking around."""
    return _gait(replace(_WALK, step_hz=step_hz, speed_cm_s=speed_cm_s, look_deg=look_deg), duration_s, fps, seed, ramp, impacts)


def run(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, step_hz: float = 2.8,
        speed_cm_s: float = 300.0, look_deg: float = _RUN.look_deg, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Running: ~2.8 steps/s, free fall between steps, ~1 g stance peaks, looking around."""
    return _gait(replace(_RUN, step_hz=step_hz, speed_cm_s=speed_cm_s, look_deg=look_deg), duration_s, fps, seed, ramp, impacts)


def hop(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, hop_hz: float = 2.0,
        speed_cm_s: float = 40.0, look_deg: float = _HOP.look_deg, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Hopping: ~2 hops/s, ~6 cm flights, 1.2-1.5 g landing peaks, turning about."""
    return _gait(replace(_HOP, step_hz=hop_hz, speed_cm_s=speed_cm_s, look_deg=look_deg), duration_s, fps, seed, ramp, impacts)


def platform(freq_hz: float, amplitude_cm: float, duration_s: float = 4.0, fps: float = 120.0,
             seed: int = 0, *, ramp: Ramp = Ramp(), axis: str = "up") -> SkullTrajectory:
    """Standing on a vibrating platform (the papers' corpus shakes vertically at 6-11 Hz).

    The sinusoid along `axis` (PLATFORM_AXES) has peak `amplitude_cm`; real platforms and
    bodies add small motion along the other two axes (5 % of the amplitude) and rocking
    (0.3 degrees per cm of amplitude) at the same frequency, with phases drawn from `seed`.
    A session shaken only vertically leaves a response little to learn sideways motion from
    (README: where the response misses next).
    """
    if not freq_hz > 0:
        raise ValueError(f"platform frequency must be positive, got {freq_hz} Hz")
    if not amplitude_cm >= 0:
        raise ValueError(f"platform amplitude must be >= 0, got {amplitude_cm} cm")
    if not freq_hz < fps / 2:
        raise ValueError(f"a {freq_hz} Hz platform needs fps above {2 * freq_hz}, got {fps}")
    if axis not in PLATFORM_AXES:
        raise ValueError(f"a platform shakes along one of {', '.join(PLATFORM_AXES)}, got {axis!r}")
    times = _times(duration_s, fps)
    rng = np.random.default_rng(seed)
    envelope = ramp.envelope(times, duration_s)
    angle = 2 * np.pi * freq_hz * times
    phases = rng.uniform(0.0, 2 * np.pi, 5)
    shares = np.full(3, 0.05)
    shares[PLATFORM_AXES[axis]] = 1.0
    translate = amplitude_cm * envelope[:, None] * np.stack([shares[k] * np.sin(angle + phases[k]) for k in range(3)], axis=1)
    rock = np.radians(0.3) * amplitude_cm * envelope
    orient = _yaw_pitch_roll(np.zeros_like(times), rock * np.sin(angle + phases[3]), rock * np.sin(angle + phases[4]))
    return SkullTrajectory(translate, orient, fps)


def parse_platform(text: str) -> tuple[float, str]:
    """(frequency in Hz, axis) of a platform motion's argument: '9', '9hz' or '4hz:side'."""
    frequency, _, axis = text.partition(":")
    try:
        hz = float(frequency.strip().lower().removesuffix("hz"))
    except ValueError:
        raise ValueError(f"platform motion needs a frequency, e.g. platform:9hz or platform:4hz:side, got {text!r}") from None
    axis = axis.strip().lower() or "up"
    if axis not in PLATFORM_AXES:
        raise ValueError(f"a platform shakes along one of {', '.join(PLATFORM_AXES)}, got {axis!r} in {text!r}")
    return hz, axis


def still(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, sway_cm: float = 0.0) -> SkullTrajectory:
    """A head at rest at the origin; `sway_cm` > 0 adds slow postural sway drawn from `seed`."""
    if not sway_cm >= 0:
        raise ValueError(f"sway must be >= 0, got {sway_cm} cm")
    times = _times(duration_s, fps)
    rng = np.random.default_rng(seed)
    translate = sway_cm * np.stack([_drift(rng, times), 0.2 * _drift(rng, times), _drift(rng, times)], axis=1)
    return SkullTrajectory(translate, quaternion.identity((len(times),)), fps)


MOCAP_LOWPASS_HZ = 10.0
"""Optical mocap differentiated twice turns marker jitter into 2-4 g spikes no skull has;
a zero-phase low-pass at 10 Hz keeps gait, hops and the papers' 6-11 Hz band."""


def from_bvh(path: str | PathLike, joint: str = "Head", duration_s: float | None = None, fps: float | None = None,
             seed: int | None = None, *, units: float | None = None, up: str | None = None,
             forward: str | None = None, lowpass_hz: float | None = MOCAP_LOWPASS_HZ) -> SkullTrajectory:
    """A real skull trajectory from motion capture (see facedyn.io.bvh.head_trajectory).

    `units`, `up` and `forward` are the file's (None: inferred, see
    facedyn.io.bvh.conventions); `fps` resamples (None keeps the file's rate);
    `duration_s` cuts a window, from the start when `seed` is None, else from a start
    drawn from `seed`; `lowpass_hz` filters the capture first (None, or a capture with
    nothing above it, at 2 x lowpass_hz fps or less: raw).
    """

    trajectory = head_trajectory(path, joint, units=units, up=up, forward=forward)
    if lowpass_hz is not None and lowpass_hz < trajectory.fps / 2:
        trajectory = lowpass(trajectory, lowpass_hz)
    if fps is not None:
        trajectory = resample(trajectory, fps)
    if duration_s is None:
        return trajectory
    frames = len(_times(duration_s, trajectory.fps))
    if frames > trajectory.frame_count:
        raise ValueError(f"{path}: holds {trajectory.frame_count / trajectory.fps:.2f} s, asked for {duration_s} s")
    start = 0 if seed is None else int(np.random.default_rng(seed).integers(0, trajectory.frame_count - frames + 1))
    window = slice(start, start + frames)
    return SkullTrajectory(trajectory.translate[window], trajectory.orient[window], trajectory.fps)


def lowpass(trajectory: SkullTrajectory, cutoff_hz: float) -> SkullTrajectory:
    """Zero-phase 4th-order Butterworth low-pass of translation and (sign-continuous) rotation."""
    from scipy.signal import butter, filtfilt

    nyquist = trajectory.fps / 2
    if not 0 < cutoff_hz < nyquist:
        raise ValueError(f"low-pass cutoff must be in (0, {nyquist:g}) Hz for {trajectory.fps:g} fps, got {cutoff_hz}")
    if trajectory.frame_count < 16:
        return trajectory
    b, a = butter(4, cutoff_hz / nyquist)
    translate = filtfilt(b, a, trajectory.translate, axis=0)
    orient = quaternion.normalize(filtfilt(b, a, quaternion.make_continuous(trajectory.orient), axis=0))
    return SkullTrajectory(translate, orient, trajectory.fps)


def resample(trajectory: SkullTrajectory, fps: float, method: str = "cubic") -> SkullTrajectory:
    """Resample over the same time span: translation by cubic spline or linearly, rotation by slerp."""
    if method not in ("cubic", "linear"):
        raise ValueError(f"method must be 'cubic' or 'linear', got {method!r}")
    times = trajectory.times
    new_times = time_grid(0.0, times[-1], fps)
    lo, hi, w = bracket(times, new_times)
    if method == "cubic" and trajectory.frame_count >= 2:
        from scipy.interpolate import CubicSpline  # here: half a second of start-up for every command that reads a motion

        translate = CubicSpline(times, trajectory.translate, axis=0)(new_times)
    else:
        translate = trajectory.translate[lo] * (1 - w)[:, None] + trajectory.translate[hi] * w[:, None]
    orient = quaternion.make_continuous(quaternion.slerp(trajectory.orient[lo], trajectory.orient[hi], w))
    return SkullTrajectory(translate, orient, fps)


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Finite-difference derivatives of a skull trajectory, each (F, 3), in world and skull axes.

    Linear acceleration is the skull origin's (cm/s^2), without gravity; angular velocity
    (rad/s) and acceleration (rad/s^2) are the skull's. Skull-axis values are the world
    vectors rotated by R(orient)^T, the form a simulator in the skull frame needs.
    """

    linear_acceleration_world: np.ndarray
    linear_acceleration_skull: np.ndarray
    angular_velocity_world: np.ndarray
    angular_velocity_skull: np.ndarray
    angular_acceleration_world: np.ndarray
    angular_acceleration_skull: np.ndarray


def accelerations(trajectory: SkullTrajectory) -> Kinematics:
    """Central differences inside, one-sided at the ends (the end accelerations repeat their neighbours)."""
    if trajectory.frame_count < 3:
        raise ValueError(f"accelerations need at least 3 frames, got {trajectory.frame_count}")
    dt = 1.0 / trajectory.fps
    x, q = trajectory.translate, trajectory.orient
    linear = np.empty_like(x)
    linear[1:-1] = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / dt**2
    linear[0], linear[-1] = linear[1], linear[-2]
    # q[t+1] = dq * q[t-1] with dq a world-axis rotation over 2 dt.
    omega = np.empty_like(x)
    omega[1:-1] = quaternion.to_rotvec(quaternion.multiply(q[2:], quaternion.conjugate(q[:-2]))) / (2.0 * dt)
    omega[0] = quaternion.to_rotvec(quaternion.multiply(q[1], quaternion.conjugate(q[0]))) / dt
    omega[-1] = quaternion.to_rotvec(quaternion.multiply(q[-1], quaternion.conjugate(q[-2]))) / dt
    alpha = np.gradient(omega, dt, axis=0)
    inverse = quaternion.conjugate(q)
    return Kinematics(
        linear_acceleration_world=linear,
        linear_acceleration_skull=quaternion.rotate(inverse, linear),
        angular_velocity_world=omega,
        angular_velocity_skull=quaternion.rotate(inverse, omega),
        angular_acceleration_world=alpha,
        angular_acceleration_skull=quaternion.rotate(inverse, alpha),
    )


def _times(duration_s: float, fps: float) -> np.ndarray:
    if not (duration_s > 0 and fps > 0):
        raise ValueError(f"duration_s and fps must be positive, got {duration_s} s at {fps} fps")
    return np.arange(max(int(round(duration_s * fps)), 1)) / fps


def _drift(rng: np.random.Generator, times: np.ndarray) -> np.ndarray:
    """Smooth random wander within [-1, 1]: three slow (0.1-0.4 Hz) sinusoids."""
    freqs = rng.uniform(0.1, 0.4, 3)[:, None]
    phases = rng.uniform(0.0, 2 * np.pi, 3)[:, None]
    return np.sin(2 * np.pi * freqs * times + phases).mean(axis=0)


def _integral(values: np.ndarray, fps: float) -> np.ndarray:
    """Cumulative trapezoid integral from time 0."""
    return np.concatenate([[0.0], np.cumsum(0.5 * (values[1:] + values[:-1]))]) / fps


def _ballistic(phase: np.ndarray, flight: float, step_hz: float) -> np.ndarray:
    """Head height (cm) over steps with a free-fall flight and a half-sine stance push.

    Takeoff is at phase 0 with speed v0 = g Tf / 2; the stance lasts Ts and its upward
    acceleration (pi v0 / Ts) sin(pi s / Ts) turns the landing speed -v0 into +v0, so the
    height is C1 and periodic, and the stance peak is pi g Tf / (2 Ts).
    """
    period = 1.0 / step_hz
    airborne, stance = flight * period, (1.0 - flight) * period
    v0 = 0.5 * G_CM_S2 * airborne
    t = np.mod(phase / (2 * np.pi), 1.0) * period
    s = t - airborne
    return np.where(
        t < airborne,
        v0 * t - 0.5 * G_CM_S2 * t * t,
        -(v0 * stance / np.pi) * np.sin(np.pi * np.clip(s, 0.0, stance) / stance),
    )


def _gait(gait: _Gait, duration_s: float, fps: float, seed: int, ramp: Ramp, impacts: bool = False) -> SkullTrajectory:
    if not (gait.step_hz > 0 and gait.speed_cm_s >= 0):
        raise ValueError(f"step rate must be positive and speed >= 0, got {gait.step_hz} Hz and {gait.speed_cm_s} cm/s")
    if not 0 <= gait.look_deg <= 180:
        raise ValueError(f"look_deg must be in [0, 180] degrees, got {gait.look_deg}")
    times = _times(duration_s, fps)
    rng = np.random.default_rng(seed)
    envelope = ramp.envelope(times, duration_s)
    tempo = gait.step_hz * (1.0 + 0.02 * _drift(rng, times))
    phase = rng.uniform(0.0, 2 * np.pi) + 2 * np.pi * _integral(tempo, fps)
    scale = rng.uniform(0.9, 1.1, 6)
    shift = rng.uniform(0.0, 2 * np.pi, 6)

    if gait.flight > 0:
        vertical = _ballistic(phase, float(np.clip(gait.flight + rng.uniform(-0.02, 0.02), 0.05, 0.9)), gait.step_hz)
    else:
        vertical = gait.bob_cm * scale[0] * (np.cos(phase) + 0.08 * np.cos(2 * phase + shift[0]))
    speed = gait.speed_cm_s * (1.0 + 0.05 * _drift(rng, times))
    forward = _integral(speed * envelope, fps) + envelope * gait.surge_cm * scale[1] * np.sin(phase + shift[1])
    lateral = envelope * gait.sway_cm * scale[2] * np.sin(0.5 * phase + shift[2])
    translate = np.stack([lateral, envelope * vertical, forward], axis=1)

    look_yaw, look_pitch = _head_turns(times, rng, np.radians(gait.look_deg))
    pitch = envelope * (np.radians(gait.pitch_deg) * scale[3] * np.sin(phase + shift[3]) + look_pitch)
    yaw = envelope * (np.radians(gait.yaw_deg) * scale[4] * np.sin(0.5 * phase + shift[4]) + look_yaw)
    roll = envelope * np.radians(gait.roll_deg) * scale[5] * np.sin(0.5 * phase + shift[5])
    orient = _yaw_pitch_roll(yaw, pitch, roll)
    if impacts and gait.impact_g > 0:
        contact = 2 * np.pi * (gait.flight if gait.flight > 0 else 0.5)  # landing, or the bob's lowest point
        jolt, turn = _contact_transients(times, phase, contact, gait.impact_g, envelope, np.random.default_rng([int(seed), 4]))
        translate = translate + jolt
        orient = quaternion.multiply(orient, quaternion.from_rotvec(turn))
    return SkullTrajectory(translate, orient, fps)


IMPACT_HZ = (6.0, 16.0)
"""Frequency range of the contact transients: what the body passes on of a foot strike."""
IMPACT_TURN_PER_G = 40.0
"""Peak angular acceleration (rad/s^2) of a contact transient per g of its linear peak."""


def _contact_transients(times, phase, contact, impact_g, envelope, rng) -> tuple[np.ndarray, np.ndarray]:
    """(offsets (F, 3) cm, rotation vectors (F, 3) rad in the head's axes): a short ringing
    jolt at each foot contact, where `phase` passes `contact` (mod 2 pi).

    Why: a foot strike is a shock that the legs, spine and neck pass on to the head as a
    transient of a few tenths of a g (walking) to a g or more (running, landing), ringing at
    6-16 Hz (rising over a cycle or two, dying out over a few more), with a nod. Smooth
    sinusoidal gaits have almost no head acceleration at 6-15 Hz, where the face's soft
    tissue resonates, while real mocap of walking and hopping has a quarter to a third of
    its angular acceleration power there (benchmarks/bench_motion_spectrum.py). Each jolt
    draws its frequency, damping, direction (mostly vertical) and size (0.5-2 x impact_g,
    log-uniform: shoes, ground and stride vary the shock several-fold);
    its displacement is a sine under a smooth envelope rising from zero, so accelerations
    stay continuous. Amplitudes are general figures of gait, not fitted to any capture.
    """
    jolt, turn = np.zeros((len(times), 3)), np.zeros((len(times), 3))
    steps = np.floor((phase - contact) / (2 * np.pi))
    for k in np.flatnonzero(np.diff(steps) > 0) + 1:
        hz, zeta = rng.uniform(*IMPACT_HZ), rng.uniform(0.3, 0.6)
        omega = 2 * np.pi * hz
        x = np.clip(times - times[k], 0.0, None) * omega * zeta / 2.0  # the envelope peaks at x = 1
        shape = x * x * np.exp(2.0 * (1.0 - x)) * np.sin(omega * (times - times[k])) / omega**2  # zero before the contact (x = 0)
        peak = impact_g * G_CM_S2 * np.exp(rng.uniform(np.log(0.5), np.log(2.0))) * envelope[k]
        direction = np.array([rng.uniform(-0.3, 0.3), -rng.uniform(0.6, 1.0), rng.uniform(-0.5, 0.5)])
        nod = np.array([rng.uniform(-1.0, 1.0), rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5)])
        jolt += peak * direction[None] * shape[:, None]
        turn += peak / G_CM_S2 * IMPACT_TURN_PER_G * nod[None] * shape[:, None]
    return jolt, turn


def _head_turns(times: np.ndarray, rng: np.random.Generator, look: float) -> tuple[np.ndarray, np.ndarray]:
    """(yaw, pitch) in radians: a head looking around, one turn every 0.6-1.6 s.

    Each turn moves to a new direction (yaw within +-look, pitch within +-look / 4) along a
    minimum-jerk profile lasting 0.25-0.6 s, or longer where needed to keep its peak angular
    speed (1.875 x angle / duration) under LOOK_MAX_DEG_S.
    """
    yaw, pitch = np.zeros_like(times), np.zeros_like(times)
    if look == 0 or len(times) < 2:
        return yaw, pitch
    start, current = rng.uniform(0.2, 0.8), np.zeros(2)
    while start < times[-1]:
        target = rng.uniform(-1.0, 1.0, 2) * np.array([look, 0.25 * look])
        change = target - current
        duration = max(rng.uniform(0.25, 0.6), 1.875 * np.abs(change).max() / np.radians(LOOK_MAX_DEG_S))
        profile = _fade(times - start, duration)
        yaw += change[0] * profile
        pitch += change[1] * profile
        current = target
        start += duration + rng.uniform(0.35, 1.0)
    return yaw, pitch


def _yaw_pitch_roll(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(F, 4) orientations: yaw about Y, then pitch about X, then roll about Z (intrinsic)."""
    axes = np.eye(3)
    q = quaternion.multiply(quaternion.from_axis_angle(axes[1], yaw), quaternion.from_axis_angle(axes[0], pitch))
    return quaternion.multiply(q, quaternion.from_axis_angle(axes[2], roll))


# Training-only motion sources (issue 18): more of what real mocap holds than walking,
# running and hopping, set from general figures of each activity, not fitted to any
# capture (the test takes' CMU subject 131 in particular). Each draws its tempo from `seed`.
_DANCE = _Gait(step_hz=2.0, speed_cm_s=0.0, flight=0.0, bob_cm=3.0, surge_cm=1.5, sway_cm=4.0, pitch_deg=8.0, yaw_deg=6.0, roll_deg=5.0, look_deg=45.0, impact_g=0.5)
_TURN = _Gait(step_hz=1.6, speed_cm_s=40.0, flight=0.0, bob_cm=1.2, surge_cm=0.5, sway_cm=1.5, pitch_deg=2.0, yaw_deg=2.0, roll_deg=1.5, look_deg=170.0, impact_g=0.3)
_JUMP = _Gait(step_hz=1.0, speed_cm_s=20.0, flight=0.35, bob_cm=0.0, surge_cm=1.5, sway_cm=0.5, pitch_deg=6.0, yaw_deg=1.0, roll_deg=1.0, look_deg=30.0, impact_g=1.5)


def dance(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Dancing on the spot: a 3 cm bounce and 8 degree head nods on a 1.7-2.5 beats/s tempo,
    4 cm sway at half the tempo, head turns within 45 degrees."""
    tempo = float(np.random.default_rng([int(seed), 1]).uniform(1.7, 2.5))
    return _gait(replace(_DANCE, step_hz=tempo), duration_s, fps, seed, ramp, impacts)


def turn(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Slow steps while turning about: yaw swings of up to 170 degrees either way at up to
    LOOK_MAX_DEG_S, 1.4-1.8 steps/s."""
    steps = float(np.random.default_rng([int(seed), 2]).uniform(1.4, 1.8))
    return _gait(replace(_TURN, step_hz=steps), duration_s, fps, seed, ramp, impacts)


def jump(duration_s: float = 4.0, fps: float = 120.0, seed: int = 0, *, ramp: Ramp = Ramp(), impacts: bool = False) -> SkullTrajectory:
    """Repeated two-footed jumps: 0.9-1.2 jumps/s, a third of each in free fall, the head
    travelling about 50-60 cm from the crouch to the top, accelerations up to about 1 g."""
    rate = float(np.random.default_rng([int(seed), 3]).uniform(0.9, 1.2))
    return _gait(replace(_JUMP, step_hz=rate), duration_s, fps, seed, ramp, impacts)
