"""Stabilization: the rigid skull motion of a tracked face (papers/001, mode pursuit) and
the simple baselines (three-point, Procrustes, robust ICP). Arrays in, arrays out."""
from facedyn.stabilize.api import METHODS, SOLVERS, StabilizeResult, stabilize
from facedyn.stabilize.schedule import REFERENCE_FPS, Schedule

__all__ = ["METHODS", "REFERENCE_FPS", "SOLVERS", "Schedule", "StabilizeResult", "stabilize"]
