"""BVH motion capture: hierarchy, channels, forward kinematics, and a head's skull motion.

facedyn reads BVH files for real skull trajectories: the head of a walking or hopping
performer moves exactly the way that makes a face jiggle (see facedyn.motion).

Conventions (the common reading of BVH, as in the CMU conversions):
- a joint's local transform translates by OFFSET plus its position channels, then rotates
  by its rotation channels composed in file order, in degrees:
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` means ``R = Rz @ Rx @ Ry``;
- world transforms: ``R_j = R_parent @ R_local`` and
  ``p_j = p_parent + R_parent @ (offset + positions)``.

Units and axes: a BVH file says neither. `conventions` takes them from the file where it
can and from arguments where it cannot (see there); `head_trajectory` then refuses a
result no human head makes (far above a human height over the floor, or sustained
accelerations of several g), naming the file and what to set.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from os import PathLike

import numpy as np

from facedyn.errors import UsageError
from facedyn.geometry import quaternion
from facedyn.io.errors import InputError, quoted
from facedyn.io.files import read_lines
from facedyn.performance import SkullTrajectory

G_M_S2 = 9.80665
"""Standard gravity, m/s^2 (SciPy's constants.g, without SciPy's import)."""

CMU_UNIT_CM = 5.64
"""Centimetres per BVH unit in the CMU database: its "scaled inches" (1 unit = 1/0.45 in)."""

UNITS_CM = {"mm": 0.1, "cm": 1.0, "inch": 2.54, "CMU unit": CMU_UNIT_CM, "foot": 30.48, "m": 100.0}
"""The units BVH exporters use, in cm; a skeleton's height picks one when the file is not CMU's."""

HUMAN_HEIGHT_CM = (100.0, 250.0)
"""Rest-pose skeleton heights (toes to head end) accepted as human when inferring units."""

MAX_HEAD_HEIGHT_CM = 250.0
"""The highest a head joint may typically be over the skeleton's lowest point."""

MAX_SUSTAINED_G = 2.5
"""The largest head acceleration accepted as a one-second average (CMU walks and hops: 0.5-0.7 g)."""

MAX_VALUE = 1e6
"""The largest magnitude of an OFFSET or channel value (file units or degrees)."""

FRAME_TIME_S = (1e-4, 10.0)
"""Accepted Frame Time range: 0.1 to 10,000 frames per second."""

_CMU_JOINTS = {"lhipjoint", "rhipjoint", "lowerback"}
_AXIS_TOLERANCE_DEG = 30.0
_FK_VALUES_PER_CHUNK = 1 << 20  # frames x joints per forward-kinematics pass (~100 MB)
_ROTATIONS = {"Xrotation": 0, "Yrotation": 1, "Zrotation": 2}
_POSITIONS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
_AXES = {
    "+x": (1.0, 0.0, 0.0), "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0), "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0), "-z": (0.0, 0.0, -1.0),
}


@dataclass(frozen=True, eq=False)
class Joint:
    """One ROOT or JOINT: its offset from the parent and where its channels are."""

    name: str
    parent: int  # index into Bvh.joints, -1 for a root
    offset: np.ndarray  # (3,) in file units
    channels: tuple[str, ...]
    first_column: int  # column of its first channel in Bvh.values
    end_site: np.ndarray | None  # (3,) offset of its End Site, if it has one


@dataclass(frozen=True, eq=False)
class Bvh:
    """A parsed BVH file; joints are listed parents first."""

    path: str
    joints: tuple[Joint, ...]
    frame_time: float
    values: np.ndarray  # (F, C) channel values in file order

    @property
    def fps(self) -> float:
        """1 / Frame Time, snapped to a whole rate when the file rounded it (.0083333 -> 120)."""
        whole = round(1.0 / self.frame_time)
        if whole > 0 and abs(1.0 / whole - self.frame_time) <= 1e-4 * self.frame_time:
            return float(whole)
        return 1.0 / self.frame_time

    @property
    def frame_count(self) -> int:
        return self.values.shape[0]

    @property
    def joint_names(self) -> list[str]:
        return [joint.name for joint in self.joints]

    def joint_index(self, name: str) -> int:
        names = self.joint_names
        if name not in names:
            shown = ", ".join(names[:40]) + (f", ... ({len(names)} joints)" if len(names) > 40 else "")
            raise InputError(self.path, f"no joint named {quoted(name)}; joints: {shown}")
        return names.index(name)


class _Tokens:
    """Whitespace tokens of the HIERARCHY section, each with its line number."""

    def __init__(self, path: str, lines: list[str]) -> None:
        self.path = path
        self.items = [(token, number) for number, line in enumerate(lines, 1) for token in line.split()]
        self.pos = 0
        self.last_line = max(len(lines), 1)

    def more(self) -> bool:
        return self.pos < len(self.items)

    def next(self, what: str) -> tuple[str, int]:
        if not self.more():
            raise InputError(self.path, f"hierarchy ends where {what} was expected", self.last_line)
        self.pos += 1
        return self.items[self.pos - 1]

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.more() else None

    def expect(self, word: str) -> int:
        token, line = self.next(repr(word))
        if token != word:
            raise InputError(self.path, f"expected {word!r}, got {quoted(token)}", line)
        return line

    def number(self, what: str) -> float:
        token, line = self.next(what)
        try:
            value = float(token)
        except ValueError:
            raise InputError(self.path, f"expected {what}, got {quoted(token)}", line) from None
        if not abs(value) <= MAX_VALUE:
            raise InputError(self.path, f"{what} {quoted(token)} is not a finite number within ±{MAX_VALUE:g}", line)
        return value

    def offset(self) -> np.ndarray:
        self.expect("OFFSET")
        return np.array([self.number("an OFFSET value") for _ in range(3)])


@dataclass
class _OpenJoint:
    """A joint whose block is still being read."""

    index: int
    name: str
    parent: int
    offset: np.ndarray
    channels: tuple[str, ...]
    first_column: int
    end_site: np.ndarray | None = None

    def closed(self) -> Joint:
        return Joint(self.name, self.parent, self.offset, self.channels, self.first_column, self.end_site)


def read_bvh(path: str | PathLike) -> Bvh:
    """Parse a BVH file; any problem is an InputError naming the file and line."""
    path = str(path)
    lines = read_lines(path)
    first = next(((number, line.split()[0]) for number, line in enumerate(lines, 1) if line.split()), None)
    if first is None or first[1] != "HIERARCHY":
        raise InputError(path, "not a BVH file: it does not start with HIERARCHY", first and first[0])
    motion = next((i for i, line in enumerate(lines) if line.split()[:1] == ["MOTION"]), None)
    if motion is None:
        raise InputError(path, "no MOTION section")
    tokens = _Tokens(path, lines[:motion])
    tokens.expect("HIERARCHY")
    joints, columns = _parse_hierarchy(tokens)
    if not joints:
        raise InputError(path, "no ROOT joint in HIERARCHY", motion)
    frame_time, values = _parse_motion(path, lines, motion, columns)
    return Bvh(path, tuple(joints), frame_time, values)


def _parse_hierarchy(tokens: _Tokens) -> tuple[list[Joint], int]:
    """Every joint, parents first, and the channel count; iterative, so any depth parses."""
    joints: list[Joint | None] = []
    names: set[str] = set()
    open_joints: list[_OpenJoint] = []
    column = 0
    while open_joints or tokens.more():
        if not open_joints:
            tokens.expect("ROOT")
            parent = -1
        else:
            token, line = tokens.next("JOINT, End Site or '}'")
            if token == "}":
                done = open_joints.pop()
                joints[done.index] = done.closed()
                continue
            if token == "End":
                tokens.expect("Site")
                tokens.expect("{")
                open_joints[-1].end_site = tokens.offset()
                tokens.expect("}")
                continue
            if token != "JOINT":
                raise InputError(tokens.path, f"expected JOINT, End Site or '}}', got {quoted(token)}", line)
            parent = open_joints[-1].index
        name, line = tokens.next("a joint name")
        if name in names:
            raise InputError(tokens.path, f"duplicate joint name {quoted(name)}", line)
        names.add(name)
        tokens.expect("{")
        offset = tokens.offset()
        channels = _channels(tokens)
        open_joints.append(_OpenJoint(len(joints), name, parent, offset, channels, column))
        joints.append(None)  # keeps parents before children; filled in when the block closes
        column += len(channels)
    return joints, column


def _channels(tokens: _Tokens) -> tuple[str, ...]:
    """The joint's CHANNELS list, empty when it has none."""
    if tokens.peek() != "CHANNELS":
        return ()
    tokens.next("CHANNELS")
    count_text, count_line = tokens.next("a channel count")
    if not (count_text.isascii() and count_text.isdigit()):
        raise InputError(tokens.path, f"expected a channel count, got {quoted(count_text)}", count_line)
    channels = []
    for _ in range(int(count_text)):
        token, line = tokens.next("a channel name")
        if token not in _ROTATIONS and token not in _POSITIONS:
            raise InputError(tokens.path, f"unknown channel {quoted(token)}", line)
        channels.append(token)
    return tuple(channels)


def _parse_motion(path: str, lines: list[str], motion: int, columns: int) -> tuple[float, np.ndarray]:
    """Frame Time and the (F, columns) values after the MOTION line (0-based index)."""
    rows = [(number, line) for number, line in enumerate(lines[motion + 1 :], motion + 2) if line.strip()]
    if len(rows) < 2 or rows[0][1].split()[:1] != ["Frames:"] or rows[1][1].split()[:2] != ["Frame", "Time:"]:
        raise InputError(path, "MOTION must be followed by 'Frames: N' and 'Frame Time: T'", motion + 1)
    (frames_line, frames_text), (time_line, time_text) = rows[0], rows[1]
    try:
        frames = int(frames_text.split()[1])
    except (IndexError, ValueError):
        raise InputError(path, "'Frames:' needs a whole number", frames_line) from None
    try:
        frame_time = float(time_text.split()[2])
    except (IndexError, ValueError):
        raise InputError(path, "'Frame Time:' needs a number", time_line) from None
    low, high = FRAME_TIME_S
    if not low <= frame_time <= high:
        raise InputError(path, f"Frame Time must be {low:g} to {high:g} seconds ({1 / high:g} to {1 / low:g} fps), got {frame_time:g}", time_line)
    data = rows[2:]
    if frames < 1:
        raise InputError(path, f"'Frames:' must be at least 1, got {frames}", frames_line)
    if len(data) != frames:
        raise InputError(path, f"header says {frames} frames but the file has {len(data)}", frames_line)
    values = np.empty((frames, columns))
    for row, (number, line) in enumerate(data):
        words = line.split()
        if len(words) != columns:
            raise InputError(path, f"expected {columns} channel values, got {len(words)}", number)
        try:
            values[row] = np.array(words, dtype=np.float64)
        except ValueError:
            raise InputError(path, "channel values must be numbers", number) from None
    bad = np.flatnonzero(~(np.abs(values) <= MAX_VALUE).all(axis=1))
    if bad.size:
        raise InputError(path, f"channel values must be finite numbers within ±{MAX_VALUE:g}", data[bad[0]][0])
    return frame_time, values


def _axis_rotations(axis: int, degrees: np.ndarray) -> np.ndarray:
    """(F,) angles about one coordinate axis -> (F, 3, 3) rotation matrices."""
    radians = np.radians(degrees)
    c, s = np.cos(radians), np.sin(radians)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m = np.zeros(radians.shape + (3, 3))
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


def forward_kinematics(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (F, J, 3, 3) and positions (F, J, 3, file units) of every joint."""
    f, n = bvh.frame_count, len(bvh.joints)
    rotations = np.empty((f, n, 3, 3))
    positions = np.empty((f, n, 3))
    for j, joint in enumerate(bvh.joints):
        local_rotation = np.broadcast_to(np.eye(3), (f, 3, 3))
        local_translation = np.tile(joint.offset, (f, 1))
        for k, channel in enumerate(joint.channels):
            column = bvh.values[:, joint.first_column + k]
            if channel in _ROTATIONS:
                local_rotation = local_rotation @ _axis_rotations(_ROTATIONS[channel], column)
            else:
                local_translation[:, _POSITIONS[channel]] += column
        if joint.parent < 0:
            rotations[:, j] = local_rotation
            positions[:, j] = local_translation
        else:
            parent_rotation = rotations[:, joint.parent]
            rotations[:, j] = parent_rotation @ local_rotation
            positions[:, j] = positions[:, joint.parent] + np.einsum("fij,fj->fi", parent_rotation, local_translation)
    return rotations, positions


def rest_positions(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """Rest-pose (all channels zero) positions of the joints (J, 3) and End Sites (E, 3)."""
    joints = np.zeros((len(bvh.joints), 3))
    ends = []
    for j, joint in enumerate(bvh.joints):
        joints[j] = joint.offset + (joints[joint.parent] if joint.parent >= 0 else 0.0)
        if joint.end_site is not None:
            ends.append(joints[j] + joint.end_site)
    return joints, np.array(ends).reshape(-1, 3)


def rest_basis(rest_forward: str = "+z", rest_up: str = "+y") -> np.ndarray:
    """The rotation taking a file's axes to facedyn's (X left, Y up, Z forward).

    `rest_forward` and `rest_up` name the axes the skeleton faces and stands along in its
    rest pose ("+z", "-x", ...); CMU and most BVH exporters use +Z and +Y.
    """
    if rest_forward not in _AXES or rest_up not in _AXES:
        raise UsageError(f"BVH axes must be one of {', '.join(_AXES)}, got forward {rest_forward!r} and up {rest_up!r}")
    forward, up = np.array(_AXES[rest_forward]), np.array(_AXES[rest_up])
    if forward @ up != 0.0:
        raise UsageError(f"BVH forward axis {rest_forward!r} and up axis {rest_up!r} must be perpendicular")
    return np.stack([np.cross(up, forward), up, forward])


@dataclass(frozen=True)
class Conventions:
    """A BVH file's units and axes, and where each came from (for logs and errors)."""

    units: float  # cm per file unit
    up: str  # the file axis the skeleton stands along in its rest pose
    forward: str  # the file axis it faces
    how: str  # e.g. "units: skeleton height (cm), up: root to head, forward: toes"

    def basis(self) -> np.ndarray:
        return rest_basis(self.forward, self.up)


def conventions(bvh: Bvh, joint: str = "Head", *, units: float | None = None, up: str | None = None,
                forward: str | None = None) -> Conventions:
    """The file's units and axes: the arguments given, the rest inferred from the file.

    - up: the axis from the root to `joint` in the rest pose (within 30 degrees);
    - forward: the axis the toes point along in the rest pose (joints named *toe*, or the
      End Sites of *toe*/*foot* joints); +Z for a Y-up skeleton without toes (the BVH
      convention);
    - units: CMU's scaled inches for a CMU skeleton (LHipJoint, RHipJoint, LowerBack);
      otherwise, for a full-body skeleton (root between feet and head), the unit among
      UNITS_CM that makes its rest height a human one (HUMAN_HEIGHT_CM, nearest 170 cm).
    Whatever cannot be inferred is an InputError naming what to set.
    """
    if units is not None and not (isinstance(units, (int, float)) and 0 < units <= 1e5):
        raise UsageError(f"BVH units must be a positive number of cm per BVH unit, got {units!r}")
    for name, axis in (("up", up), ("forward", forward)):
        if axis is not None and axis not in _AXES:
            raise UsageError(f"BVH {name} axis must be one of {', '.join(_AXES)}, got {axis!r}")
    index = bvh.joint_index(joint)
    joints, ends = rest_positions(bvh)
    how = []
    if up is None:
        up = _infer_up(bvh, joints, index, joint)
        how.append(f"up {up}: root to {joint}")
    if forward is None:
        forward, source = _infer_forward(bvh, joints, up)
        how.append(f"forward {forward}: {source}")
    try:
        rest_basis(forward, up)
    except UsageError as exc:
        if not how:
            raise
        raise InputError(bvh.path, f"{exc} ({', '.join(how)})") from None  # an inferred axis against a given one
    if units is None:
        units, source = _infer_units(bvh, joints, ends, np.array(_AXES[up]))
        how.append(f"units {units:g} cm: {source}")
    return Conventions(float(units), up, forward, ", ".join(how) or "all given")


def _snap(vector: np.ndarray, candidates: list[str]) -> tuple[str, float]:
    """The candidate axis nearest `vector` and the angle to it in degrees."""
    unit = vector / np.linalg.norm(vector)
    best = max(candidates, key=lambda axis: unit @ np.array(_AXES[axis]))
    return best, float(np.degrees(np.arccos(np.clip(unit @ np.array(_AXES[best]), -1.0, 1.0))))


def _infer_up(bvh: Bvh, joints: np.ndarray, index: int, name: str) -> str:
    root = index
    while bvh.joints[root].parent >= 0:
        root = bvh.joints[root].parent
    rise = joints[index] - joints[root]
    if not np.linalg.norm(rise) > 0:
        raise InputError(bvh.path, f"cannot tell which axis is up: {name} is the root; set up (e.g. +y)")
    axis, angle = _snap(rise, list(_AXES))
    if angle > _AXIS_TOLERANCE_DEG:
        raise InputError(bvh.path, f"cannot tell which axis is up: in the rest pose {name} lies {angle:.0f} degrees from every axis above the root; set up (e.g. +y)")
    return axis


def _infer_forward(bvh: Bvh, joints: np.ndarray, up: str) -> tuple[str, str]:
    """(axis, how it was found): along the toes, else the BVH convention for Y-up files."""
    up_vector = np.array(_AXES[up])
    pointing = np.zeros(3)
    for j, joint in enumerate(bvh.joints):
        name = joint.name.lower()
        if "toe" in name and joint.parent >= 0:
            pointing += joints[j] - joints[joint.parent]
        if ("toe" in name or "foot" in name) and joint.end_site is not None:
            pointing += joint.end_site
    pointing -= (pointing @ up_vector) * up_vector
    if np.linalg.norm(pointing) > 0:
        axis, angle = _snap(pointing, [a for a, v in _AXES.items() if np.array(v) @ up_vector == 0])
        if angle <= _AXIS_TOLERANCE_DEG:
            return axis, "toes"
    if up in ("+y", "-y"):
        return "+z", "BVH convention"
    raise InputError(bvh.path, f"cannot tell which way the skeleton faces (no toes along an axis, up is {up}); set forward (e.g. -y)")


def _infer_units(bvh: Bvh, joints: np.ndarray, ends: np.ndarray, up: np.ndarray) -> tuple[float, str]:
    """(cm per unit, how it was found) from the skeleton's names or its rest height."""
    if _CMU_JOINTS <= {joint.name.lower() for joint in bvh.joints}:
        return CMU_UNIT_CM, "CMU skeleton"
    heights = np.concatenate([joints, ends]) @ up
    low, high = heights.min(), heights.max()
    tall = high - low
    root_at = (heights[0] - low) / tall if tall > 0 else 0.0
    if not 0.25 <= root_at <= 0.75:
        raise InputError(bvh.path, "cannot tell the units: not a full-body skeleton (its root is not between feet and head); set units (cm per BVH unit)")
    name = min(UNITS_CM, key=lambda unit: abs(np.log(tall * UNITS_CM[unit] / 170.0)))
    if not HUMAN_HEIGHT_CM[0] <= tall * UNITS_CM[name] <= HUMAN_HEIGHT_CM[1]:
        raise InputError(bvh.path, f"cannot tell the units: the skeleton is {tall:g} units tall, no human height in {', '.join(UNITS_CM)}; set units (cm per BVH unit)")
    return UNITS_CM[name], f"skeleton height {tall * UNITS_CM[name]:.0f} cm in {name}"


def _head_and_floor(bvh: Bvh, index: int, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The joint's world rotations (F, 3, 3) and positions (F, 3), and the lowest height
    any joint or End Site reaches along `up`, computed a bounded number of frames at a time."""
    f = bvh.frame_count
    chunk = max(1, _FK_VALUES_PER_CHUNK // len(bvh.joints))
    head_rotations, head_positions = np.empty((f, 3, 3)), np.empty((f, 3))
    ends = [(j, joint.end_site) for j, joint in enumerate(bvh.joints) if joint.end_site is not None]
    floor = np.inf
    for start in range(0, f, chunk):
        rotations, positions = forward_kinematics(replace(bvh, values=bvh.values[start : start + chunk]))
        head_rotations[start : start + chunk] = rotations[:, index]
        head_positions[start : start + chunk] = positions[:, index]
        floor = min(floor, float((positions @ up).min()))
        for j, end_site in ends:
            floor = min(floor, float(((positions[:, j] + rotations[:, j] @ end_site) @ up).min()))
    return head_rotations, head_positions, floor


def sustained_acceleration_g(translate: np.ndarray, fps: float) -> float:
    """The largest one-second average of the acceleration magnitude, in g.

    Accelerations are second differences over 50 ms steps, so marker jitter (which second
    differences over one frame turn into g's of noise at 120 fps and more) does not count.
    """
    step = max(1, round(0.05 * fps))
    if len(translate) < 2 * step + 1:
        return 0.0
    dt = step / fps
    accel = translate[2 * step :] - 2.0 * translate[step:-step] + translate[: -2 * step]
    magnitude = np.linalg.norm(accel, axis=1) / (dt * dt * G_M_S2 * 100.0)
    window = max(1, min(len(magnitude), round(fps)))
    sums = np.cumsum(np.concatenate([[0.0], magnitude]))
    return float(((sums[window:] - sums[:-window]) / window).max())


def head_trajectory(path: str | PathLike, joint: str = "Head", *, units: float | None = None, up: str | None = None,
                    forward: str | None = None) -> SkullTrajectory:
    """A joint's world motion as a skull trajectory: cm, Y up, facing +Z at rest.

    `units` (cm per BVH unit), `up` and `forward` (the file axes the skeleton stands along
    and faces in its rest pose, "+y", "-z", ...) default to what `conventions` infers.

    The skull frame: BVH joints carry no rest rotation, so in the rest pose (all channels
    zero) every joint frame is the file's world frame. Both the world and the joint frame
    are re-expressed in facedyn's convention (the face rig's: X left, Y up, Z forward), so
    the skull orientation is the identity when the performer stands in the rest pose facing
    forward, and the face rig can be placed in skull space as it is. The skull origin is
    the joint itself (for CMU's Head: the top of the neck).

    A result no human head makes is an InputError naming the file and what to set: the
    joint more than MAX_HEAD_HEIGHT_CM over the skeleton's lowest point, or accelerating
    by more than MAX_SUSTAINED_G on average over a second.
    """
    bvh = read_bvh(path)
    found = conventions(bvh, joint, units=units, up=up, forward=forward)
    index = bvh.joint_index(joint)
    basis = found.basis()
    rotations, positions, floor = _head_and_floor(bvh, index, basis[1])
    translate = found.units * positions @ basis.T
    orient = quaternion.make_continuous(quaternion.from_matrix(basis @ rotations @ basis.T))
    trajectory = SkullTrajectory(translate, orient, bvh.fps)
    setting = f"at {found.units:g} cm per BVH unit, up {found.up} ({found.how})"
    height = float(np.median(translate[:, 1])) - found.units * floor
    if height > MAX_HEAD_HEIGHT_CM:
        raise InputError(bvh.path, f"{joint} is {height / 100:.1f} m above the skeleton's lowest point {setting}; no head is; set units (cm per BVH unit) and up")
    sustained = sustained_acceleration_g(translate, trajectory.fps)
    if sustained > MAX_SUSTAINED_G:
        raise InputError(bvh.path, f"{joint} accelerates at {sustained:.1f} g on average over a second {setting}; no head does; set units (cm per BVH unit)")
    return trajectory
