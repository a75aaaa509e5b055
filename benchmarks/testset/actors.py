"""The test set's actors and their takes: VALIDATION (tune freely) and TEST (run once).

The rule (benchmarks/README-testset.md): a change is designed, tuned and chosen on the
VALIDATION actors only. The TEST actors are generated and scored once, when a change is
finished, and their figures go to the results page with the commit and date. A TEST actor
whose figure was used to choose anything becomes a VALIDATION actor, and a new TEST actor is
drawn from seeds never used before (append it here; never reuse a seed).
"""
from __future__ import annotations

from dataclasses import dataclass

from testset.takes import TakeRecipe

FPS = 60.0  # the captures' frame rate
# MuJoCo steps per captured frame, per face: explicit steps need about half the stability limit
# at rest (1.5 ms on the built-in face, 0.67 ms on the ICT rig's smaller elements, measured from
# the stiffness at rest; the stiffest tissue drawn shortens both by up to 1.4x; 1.19 ms diverged
# when a smile met a 5 Hz platform near the built-in face's first modes).
SUBSTEPS = {"default": 20, "ict": 48}  # 1200 Hz (0.83 ms), 2880 Hz (0.35 ms)


@dataclass(frozen=True)
class ActorSpec:
    """A test actor: a face (the built-in face or the ICT rig, with an identity drawn from
    `identity_seed`), a tissue drawn from `tissue_seed` and takes drawn from `take_seed`."""

    name: str
    face: str  # "default" (facedyn.sim.default_face) or "ict" (the shared ICT-FaceKit rig)
    identity_seed: int | None
    tissue_seed: int
    take_seed: int
    split: str  # "validation" or "test"


VALIDATION = (
    ActorSpec("val_default_2101", "default", 2101, 2101, 2101, "validation"),
    ActorSpec("val_ict_2102", "ict", 2102, 2102, 2102, "validation"),
    # the tissue range's other end (damping ratio 0.093 against val_default_2101's 0.245): a
    # lightly damped tissue rings longer than a heavily damped one, so what a response needs
    # of the skull's past is tuned on both ends
    ActorSpec("val_default_2112", "default", 2112, 2112, 2112, "validation"),  # (2103, as low, is stiff enough to diverge at 20 substeps)
)
TEST = (
    ActorSpec("test_ict_3101", "ict", 3101, 3101, 3101, "test"),
    ActorSpec("test_ict_3102", "ict", 3102, 3102, 3102, "test"),
    ActorSpec("test_default_3103", "default", 3103, 3103, 3103, "test"),
    # a second built-in-face test actor, so that the test figures do not rest on one tissue
    ActorSpec("test_default_3104", "default", 3104, 3104, 3104, "test"),
)
ACTORS = {actor.name: actor for actor in VALIDATION + TEST}


SESSION_EXPRESSIONS = ("smile", "jaw_open", "brow_raise", "pucker", "cheek_puff", "frown", "sneer", "squint", "jaw_side", "stretch")
SESSION_MOTIONS = ("platform:5", "platform:6.5", "platform:10", "platform:4:side", "platform:6:forward", "bvh:131_01.bvh", "bvh:131_03.bvh")


def session_takes(seed: int, seconds: float = 2.0) -> list[TakeRecipe]:
    """A studio's calibration session as the issue's evaluation holds one (70 takes): ten held
    expressions (not the test's funnel), each on five platforms (none at the test's 8 Hz) and
    under two real motions (CMU 131_01 walk, 131_03 hop; the test's 131_02 is not among them)."""
    plan = [(expression, motion) for expression in SESSION_EXPRESSIONS for motion in SESSION_MOTIONS]
    return [TakeRecipe(f"session_{expression}_{_label(motion)}", "session", motion, expression=expression, duration_s=seconds,
                       seed=seed + 100 + k)  # apart from the test takes' seed + 50...
            for k, (expression, motion) in enumerate(plan)]


def test_takes(seed: int, seconds: float = 2.5) -> list[TakeRecipe]:
    """Dialogs under a walk the session never has (CMU 131_02) and that walk at 1.6x (a run), a held
    expression on the held-out 8 Hz platform."""
    return [TakeRecipe("dialog_walk", "test", "bvh:131_02.bvh", dialog="S88-001.csv", duration_s=seconds, seed=seed + 50),
            TakeRecipe("dialog_run", "test", "bvh:131_02.bvh@1.6", dialog="facial.csv", duration_s=seconds, seed=seed + 51),
            TakeRecipe("platform_8hz", "test", "platform:8", expression="funnel", duration_s=seconds, seed=seed + 52)]


def transfer_takes(seed: int, seconds: float = 2.5) -> list[TakeRecipe]:
    """The walking dialog's performance under the run's skull (test_takes' recipes, so the
    expression and the skull match theirs frame for frame): what synthesizing or retargeting
    the walk's quasistatic take under the run should give. The run is new motion: the session
    has 131_01 and 131_03, not 131_02 at 1.6x."""
    walk, run, _ = test_takes(seed, seconds)
    return [TakeRecipe("walk_dialog_under_run", "transfer", run.motion, dialog=walk.dialog, duration_s=seconds, seed=walk.seed,
                       motion_seed=run.seed, sources=(walk.name, run.name))]


def cross_actor_takes(seed: int, source: ActorSpec, seconds: float = 2.5) -> list[TakeRecipe]:
    """The walking dialog's performance under another actor's run (that actor's test take's
    skull trajectory, frame for frame): what retargeting that actor's root motion onto this one
    should give. The issue's retargeting case: the other actor's tissue is not this one's, so
    copying its removed offsets (delta transfer) copies the wrong tissue's answer, where
    synthesis makes this actor's own. `source` must share this actor's face (one topology)."""
    walk, _, _ = test_takes(seed, seconds)
    _, run, _ = test_takes(source.take_seed, seconds)
    return [TakeRecipe(f"walk_dialog_under_{source.name}_run", "cross", run.motion, dialog=walk.dialog, duration_s=seconds, seed=walk.seed,
                       motion_seed=run.seed, sources=(walk.name, f"{source.name}/{run.name}"))]


def _label(motion: str) -> str:
    kind, _, arg = motion.partition(":")
    if kind == "platform":
        return "platform" + arg.replace(":", "").replace(".", "p") + ("" if ":" in arg else "hz")
    return arg.split(".")[0].replace("@", "x")
