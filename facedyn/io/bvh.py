"""BVH motion capture: hierarchy, channels and forward kinematics vectorized over frames.

facedyn reads BVH files for real skull trajectories: the head of a walking or hopping
performer moves exactly the way that makes a face jiggle (see facedyn.motion).

Conventions (the common reading of BVH, as in the CMU conversions):
- a joint's local transform translates by OFFSET plus its position channels, then rotates
  by its rotation channels composed in file order, in degrees:
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` means ``R = Rz @ Rx @ Ry``;
- world transforms: ``R_j = R_parent @ R_local`` and
  ``p_j = p_parent + R_parent @ (offset + positions)``.
"""
from __future__ import annotations

from dataclasses import dataclass
from os import PathLike

import numpy as np

from facedyn.geometry import quaternion
from facedyn.io.errors import InputError, read_lines
from facedyn.performance import SkullTrajectory

CMU_UNIT_CM = 5.64
"""Centimetres per BVH unit in the CMU database: its "scaled inches" (1 unit = 1/0.45 in)."""

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
            raise InputError(self.path, f"no joint named {name!r}; joints: {', '.join(names)}")
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
            raise InputError(self.path, f"expected {word!r}, got {token!r}", line)
        return line

    def number(self, what: str) -> float:
        token, line = self.next(what)
        try:
            return float(token)
        except ValueError:
            raise InputError(self.path, f"expected {what}, got {token!r}", line) from None


def read_bvh(path: str | PathLike) -> Bvh:
    """Parse a BVH file; any problem is an InputError naming the file and line."""
    path = str(path)
    lines = read_lines(path)
    motion = next((i for i, line in enumerate(lines) if line.split()[:1] == ["MOTION"]), None)
    if motion is None:
        raise InputError(path, "no MOTION section")
    tokens = _Tokens(path, lines[:motion])
    tokens.expect("HIERARCHY")
    joints: list = []
    columns = 0
    while tokens.more():
        tokens.expect("ROOT")
        columns = _parse_joint(tokens, joints, -1, columns)
    if not joints:
        raise InputError(path, "no ROOT joint in HIERARCHY", motion)
    frame_time, values = _parse_motion(path, lines, motion, columns)
    return Bvh(path, tuple(joints), frame_time, values)


def _parse_joint(tokens: _Tokens, joints: list, parent: int, column: int) -> int:
    """Parse one joint block (name onwards) into `joints`; returns the next free column."""
    name, line = tokens.next("a joint name")
    if any(joint is not None and joint.name == name for joint in joints):
        raise InputError(tokens.path, f"duplicate joint name {name!r}", line)
    tokens.expect("{")
    tokens.expect("OFFSET")
    offset = np.array([tokens.number("an OFFSET value") for _ in range(3)])
    channels: tuple[str, ...] = ()
    if tokens.peek() == "CHANNELS":
        tokens.next("CHANNELS")
        count_text, count_line = tokens.next("a channel count")
        if not count_text.isdigit():
            raise InputError(tokens.path, f"expected a channel count, got {count_text!r}", count_line)
        channels = tuple(_channel(tokens) for _ in range(int(count_text)))
    index = len(joints)
    joints.append(None)  # keeps parents before children; filled in below
    first_column, column = column, column + len(channels)
    end_site = None
    while True:
        token, line = tokens.next("JOINT, End Site or '}'")
        if token == "}":
            break
        if token == "JOINT":
            column = _parse_joint(tokens, joints, index, column)
        elif token == "End":
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            end_site = np.array([tokens.number("an OFFSET value") for _ in range(3)])
            tokens.expect("}")
        else:
            raise InputError(tokens.path, f"expected JOINT, End Site or '}}', got {token!r}", line)
    joints[index] = Joint(name, parent, offset, channels, first_column, end_site)
    return column


def _channel(tokens: _Tokens) -> str:
    token, line = tokens.next("a channel name")
    if token not in _ROTATIONS and token not in _POSITIONS:
        raise InputError(tokens.path, f"unknown channel {token!r}", line)
    return token


def _parse_motion(path: str, lines: list[str], motion: int, columns: int) -> tuple[float, np.ndarray]:
    """Frames, Frame Time and the (F, columns) values after the MOTION line (0-based index)."""
    rows = [(number, line.split()) for number, line in enumerate(lines[motion + 1 :], motion + 2) if line.strip()]
    if len(rows) < 2 or rows[0][1][:1] != ["Frames:"] or rows[1][1][:2] != ["Frame", "Time:"]:
        raise InputError(path, "MOTION must be followed by 'Frames: N' and 'Frame Time: T'", motion + 1)
    (frames_line, frames_words), (time_line, time_words) = rows[0], rows[1]
    try:
        frames = int(frames_words[1])
    except (IndexError, ValueError):
        raise InputError(path, "'Frames:' needs a whole number", frames_line) from None
    try:
        frame_time = float(time_words[2])
    except (IndexError, ValueError):
        raise InputError(path, "'Frame Time:' needs a number", time_line) from None
    if frame_time <= 0:
        raise InputError(path, f"Frame Time must be positive, got {frame_time}", time_line)
    data = rows[2:]
    if len(data) != frames:
        raise InputError(path, f"header says {frames} frames but the file has {len(data)}", frames_line)
    for number, words in data:
        if len(words) != columns:
            raise InputError(path, f"expected {columns} channel values, got {len(words)}", number)
    values = np.array([_numbers(path, number, words) for number, words in data], dtype=np.float64)
    return frame_time, values.reshape(frames, columns)


def _numbers(path: str, line: int, words: list[str]) -> list[float]:
    try:
        return [float(word) for word in words]
    except ValueError:
        raise InputError(path, "channel values must be numbers", line) from None


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


def rest_basis(rest_forward: str = "+z", rest_up: str = "+y") -> np.ndarray:
    """The rotation taking a file's axes to facedyn's (X left, Y up, Z forward).

    `rest_forward` and `rest_up` name the axes the skeleton faces and stands along in its
    rest pose ("+z", "-x", ...); CMU and most BVH exporters use +Z and +Y.
    """
    if rest_forward not in _AXES or rest_up not in _AXES:
        raise ValueError(f"rest axes must be one of {', '.join(_AXES)}, got {rest_forward!r} and {rest_up!r}")
    forward, up = np.array(_AXES[rest_forward]), np.array(_AXES[rest_up])
    if forward @ up != 0.0:
        raise ValueError(f"rest_forward {rest_forward!r} and rest_up {rest_up!r} must be perpendicular")
    return np.stack([np.cross(up, forward), up, forward])


def head_trajectory(
    path: str | PathLike,
    joint: str = "Head",
    units_to_cm: float | None = None,
    rest_forward: str = "+z",
    rest_up: str = "+y",
) -> SkullTrajectory:
    """A joint's world motion as a skull trajectory: cm, Y up, facing +Z at rest.

    `units_to_cm` scales file units to centimetres; None means CMU's scaled inches
    (CMU_UNIT_CM = 5.64 cm per unit).

    The skull frame: BVH joints carry no rest rotation, so in the rest pose (all channels
    zero) every joint frame is the file's world frame, and which way that faces is the
    exporter's convention (`rest_forward`, `rest_up`; +Z and +Y for CMU). Both the world and
    the joint frame are re-expressed in facedyn's convention (the face rig's: X left, Y up,
    Z forward), so the skull orientation is the identity when the performer stands in the
    rest pose facing +Z, and the face rig can be placed in skull space as it is. The skull
    origin is the joint itself (for CMU's Head: the top of the neck).
    """
    scale = CMU_UNIT_CM if units_to_cm is None else float(units_to_cm)
    if not scale > 0:
        raise ValueError(f"units_to_cm must be positive, got {units_to_cm}")
    basis = rest_basis(rest_forward, rest_up)
    bvh = read_bvh(path)
    index = bvh.joint_index(joint)
    rotations, positions = forward_kinematics(bvh)
    translate = scale * positions[:, index] @ basis.T
    orient = quaternion.make_continuous(quaternion.from_matrix(basis @ rotations[:, index] @ basis.T))
    return SkullTrajectory(translate, orient, bvh.fps)
