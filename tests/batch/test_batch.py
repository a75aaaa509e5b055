"""`usdfacedyn batch` and `simulate` on a local Dask cluster of 2 worker processes, on small
simulated takes of the built-in face (a few seconds each)."""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

from facedyn.batch.cluster import open_client, run_steps  # noqa: E402
from facedyn.batch.command import add_batch_arguments, run_batch  # noqa: E402
from facedyn.batch.cluster_corpus import build_corpus_on  # noqa: E402
from facedyn.batch.plan import Models, plan_batch  # noqa: E402
from facedyn.batch.state import STATE_FILE, file_checksum  # noqa: E402
from facedyn.dynamics.face import FaceSetup  # noqa: E402
from facedyn.dynamics.modelfile import load_model, save_model  # noqa: E402
from facedyn.dynamics.synthesis_training import synthesis_config, train_synthesis  # noqa: E402
from facedyn.dynamics.training import TrainConfig, train_removal  # noqa: E402
from facedyn.dynamics.training_sequence import TrainingSequence  # noqa: E402
from facedyn.sim.corpus import TakeSpec, simulate_take  # noqa: E402
from facedyn.sim.default_face import default_face  # noqa: E402
from facedyn.usd.corpus_files import write_simulated_take  # noqa: E402
from facedyn.usd.inspect import describe_take  # noqa: E402

ALL_STEPS = "import,stabilize,remove,synthesize,preview"
OUTPUTS = {"import": "capture.usdc", "stabilize": "stabilized.usdc", "remove": "quasistatic.usdc",
           "synthesize": "synthesized.hop.usdc", "preview": "take.preview.usdc"}


@pytest.fixture(scope="module")
def rig():
    return default_face(8)


@pytest.fixture(scope="module")
def shots(tmp_path_factory, rig):
    """Three walking captures (shots/shot<i>.usdc), a corrupt one, and tiny F and H (actor.*)."""
    folder = tmp_path_factory.mktemp("shots")
    sims = [simulate_take(rig, TakeSpec(f"shot{i}", "walk", "smile", duration_s=0.4, seed=i)) for i in range(3)]
    for sim in sims:
        write_simulated_take(folder / "sim" / sim.spec.name, sim, rig)
        shutil.copy(folder / "sim" / sim.spec.name / "capture.usdc", folder / f"{sim.spec.name}.usdc")
    (folder / "broken.usdc").write_bytes(b"not a usd file")
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, sample_count=16)
    takes = [TrainingSequence(s.spec.name, s.captured, s.fps, s.skull_translate, s.skull_orient, "skull", s.offsets) for s in sims]
    save_model(train_removal(takes, face, TrainConfig(epochs=1, trim=5, target="truth")), folder / "actor.removal")
    truth = {s.spec.name: s.quasistatic for s in sims}
    save_model(train_synthesis(takes, face, rig.uvs, truth, synthesis_config(epochs=1, trim=5), backend="numpy"), folder / "actor.synthesis")
    return folder


@pytest.fixture(scope="module")
def client():
    with open_client(workers=2) as c:
        yield c


def batch_args(*argv: str):
    parser = argparse.ArgumentParser()
    add_batch_arguments(parser)
    return parser.parse_args(list(argv))


def statuses(results):
    return {(r["take"], r["step"]): r["status"] for r in results}


def layer_stack(take_folder: Path) -> list[tuple[str, str]]:
    """(file name, processor) of the take's layers below its root."""
    return [(Path(layer["layer"]).name, layer["processor"]) for layer in describe_take(take_folder / "take.usda")["layers"][1:]]


@pytest.mark.slow  # a Dask cluster runs four steps on three takes, twice
def test_a_batch_completes_and_a_rerun_skips_every_step(shots, client, tmp_path):
    out = tmp_path / "out"
    models = Models(shots / "actor.removal", shots / "actor.synthesis", "hop")
    takes = plan_batch([str(shots / "shot[01].usdc")], out, tuple(ALL_STEPS.split(",")), models)
    first = run_steps(client, takes)
    assert set(statuses(first).values()) == {"ok"}, [r for r in first if r["status"] != "ok"]
    for name in ("shot0", "shot1"):
        expected = [(OUTPUTS[s], s) for s in ("preview", "synthesize", "remove", "stabilize", "import")]
        assert layer_stack(out / name) == expected
        state = json.loads((out / name / STATE_FILE).read_text())
        assert state["capture"]["sha256"] == file_checksum(shots / f"{name}.usdc")
    again = run_steps(client, takes)
    assert set(statuses(again).values()) == {"skipped"}
    # a changed model makes its step and every later one stale, nothing before it
    model = load_model(shots / "actor.removal")
    model.info["note"] = "re-saved"  # same network, other bytes: another checksum
    save_model(model, tmp_path / "other.removal")
    other = plan_batch([str(shots / "shot0.usdc")], out, tuple(ALL_STEPS.split(",")),
                       Models(tmp_path / "other.removal", shots / "actor.synthesis", "hop"))
    changed = statuses(run_steps(client, other))
    assert changed == {("shot0", "import"): "skipped", ("shot0", "stabilize"): "skipped", ("shot0", "remove"): "ok",
                       ("shot0", "synthesize"): "ok", ("shot0", "preview"): "ok"}
    forced = run_steps(client, takes[:1], force=True)
    assert set(statuses(forced).values()) == {"ok"}


@pytest.mark.slow  # a local Dask cluster runs the steps
def test_a_bad_capture_fails_alone_with_its_error_and_exit_code(shots, tmp_path, capsys):
    args = batch_args(str(shots / "shot2.usdc"), str(shots / "broken.usdc"), str(shots / "missing.usdc"), "-o", str(tmp_path / "out"),
                      "--steps", "import,stabilize", "--workers", "2", "--json")
    assert run_batch(args) == 1
    report = json.loads(capsys.readouterr().out)
    by_take = {entry["take"]: entry for entry in report["takes"]}
    assert report["succeeded"] is False and report["workers"] == 2
    assert by_take["shot2"]["status"] == "ok"
    assert [s["status"] for s in by_take["shot2"]["steps"]] == ["ok", "ok"]
    broken = by_take["broken"]["steps"]
    assert [s["status"] for s in broken] == ["failed", "blocked"]
    assert broken[0]["error"].startswith("usdfacedyn: error:") and "broken.usdc" in broken[0]["error"]
    assert "\n" not in broken[0]["error"]
    missing = by_take["missing"]["steps"][0]
    assert missing["status"] == "failed" and "missing.usdc" in missing["error"] and "No such file" in missing["error"]
    assert layer_stack(tmp_path / "out" / "shot2") == [("stabilized.usdc", "stabilize"), ("capture.usdc", "import")]


def test_batch_usage_errors(shots, tmp_path):
    from facedyn.errors import UsageError

    with pytest.raises(UsageError, match="needs a removal model"):
        run_batch(batch_args(str(shots / "shot0.usdc"), "-o", str(tmp_path), "--steps", "import,remove"))
    with pytest.raises(UsageError, match="pipeline order"):
        run_batch(batch_args(str(shots / "shot0.usdc"), "-o", str(tmp_path), "--steps", "stabilize,import"))
    with pytest.raises(UsageError, match="matches no file"):
        run_batch(batch_args(str(shots / "nothing*.usdc"), "-o", str(tmp_path), "--steps", "import"))
    listing = tmp_path / "shots.txt"
    listing.write_text(f"# two shots\n{shots / 'shot0.usdc'}\n\n{shots / 'shot1.usdc'}\n")
    takes = plan_batch([str(listing)], tmp_path / "out", ("import",), Models())
    assert [plans[0].take for plans in takes] == ["shot0", "shot1"]


def test_batch_steps_are_the_processors_with_the_flags_they_declare(tmp_path, capsys):
    from facedyn.batch.command import models_from
    from facedyn.batch.plan import STEPS, flag
    from facedyn.errors import FacedynError, UsageError
    from facedyn.processors import registry

    files = {name: tmp_path / name for name in ("shot0.usdc", "f.removal", "h.synthesis", "actor.usda")}
    for path in files.values():
        path.write_bytes(b"")
    models = Models(files["f.removal"], files["h.synthesis"], "hop", files["actor.usda"])
    [plans] = plan_batch([str(files["shot0.usdc"])], tmp_path / "out", STEPS, models)
    assert {plan.step: plan.output.name for plan in plans} == OUTPUTS
    for plan in plans:
        declared = {p.flag for p in registry.load(plan.step).parameters} | {"--attach"}
        given = [a for a in plan.argv if a.startswith("--")]
        assert set(given) <= declared, (plan.step, given)
    argv = {plan.step: plan.argv for plan in plans}
    assert argv["remove"][argv["remove"].index("--model") + 1] == str(files["f.removal"])
    assert argv["synthesize"][argv["synthesize"].index("--model") + 1] == str(files["h.synthesis"])
    assert "--actor" in argv["stabilize"] and "--attach" not in argv["import"]
    with pytest.raises(FacedynError, match="declares no 'strength' parameter"):
        flag("remove", "strength")
    # batch's flag for remove's model is --removal-model; --model is its deprecated alias
    args = batch_args(str(files["shot0.usdc"]), "-o", str(tmp_path / "out"), "--model", str(files["f.removal"]))
    assert models_from(args).removal == files["f.removal"] and "--removal-model" in capsys.readouterr().err
    assert models_from(batch_args("x", "-o", "y", "--removal-model", "f.removal")).removal == Path("f.removal")
    with pytest.raises(UsageError, match="old name of --removal-model"):
        models_from(batch_args("x", "-o", "y", "--removal-model", "f.removal", "--model", "g.removal"))


def test_batch_options_are_the_declared_parameters_of_the_steps_in_role_order():
    """STEPS, STEP_OPTIONS and the layer names agree with the processors' declarations and the role table."""
    from facedyn.batch.plan import STEP_OPTIONS, STEPS, declaration, layer_name, options_of, step_order
    from facedyn.performance import PREVIEW, SYNTHESIZED, role

    assert STEPS == step_order(STEPS)  # the help's default lists them in the order the roles' ranks give
    taken = {step: [option.field for option, _ in options_of(step)] for step in STEPS}
    assert taken == {"import": [], "stabilize": ["actor"], "remove": ["removal"], "synthesize": ["synthesis", "skull_motion"], "preview": []}
    for step in STEPS:
        for option, parameter in options_of(step):
            assert option.file == (parameter.type is Path), option  # models_from converts as the step reads it
            assert bool(option.needs) == parameter.required, option  # a required parameter's option is checked before any take runs
    assert len({option.flag for option in STEP_OPTIONS}) == len(STEP_OPTIONS)
    assert layer_name("synthesize", "hop") == "synthesized.hop.usdc" and role(SYNTHESIZED).layer_file() == "synthesized.usdc"
    assert role(PREVIEW).layer_file("hop").endswith(".preview.usdc")  # what the preview processor asks of its output's name
    assert [role(declaration(step).writes.role).layer_file() for step in ("import", "preview")] == ["capture.usdc", "take.preview.usdc"]


def tree_checksums(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and p.name != "corpus.json"}


@pytest.mark.slow  # simulates a corpus on one and two workers
def test_simulate_on_the_cluster_writes_the_same_bytes_with_one_or_two_workers(rig, client, tmp_path):
    specs = [TakeSpec(f"take{i}", motion, "smile", duration_s=0.3, seed=i) for i, motion in enumerate(("walk", "hop", "platform:9"))]
    specs.insert(1, TakeSpec("unreadable", "still", dialog=str(tmp_path / "missing.csv"), duration_s=0.3))  # skipped, recorded
    out = tmp_path / "corpus"
    two = build_corpus_on(client, out, rig, specs)
    on_two = tree_checksums(out)
    shutil.rmtree(out)
    with open_client(workers=1) as single:
        one = build_corpus_on(single, out, rig, specs)
    assert tree_checksums(out) == on_two and len(on_two) == 6 * 3  # 5 layers and the recipe per written take
    assert one["failed"] == two["failed"] and [f["name"] for f in one["failed"]] == ["unreadable"]
    assert one["takes"] == two["takes"] and [t["name"] for t in one["takes"]] == ["take0", "take1", "take2"]
    assert (one["jobs"], two["jobs"]) == (1, 2)


@pytest.mark.slow  # a Dask cluster runs the steps while a worker is killed
def test_killing_a_worker_mid_batch_still_completes_every_take(shots, client, tmp_path):
    """Runs last in this module: the killed worker's nanny starts a new one."""
    pids = client.run(os.getpid)
    killed = []

    def kill_a_busy_worker(result, results):
        if killed:
            return
        busy = [address for address, keys in client.processing().items() if keys and address in pids]
        if busy:
            os.kill(pids[busy[0]], signal.SIGKILL)
            killed.append(busy[0])

    out = tmp_path / "out"
    takes = plan_batch([str(shots / f"shot{i}.usdc") for i in range(3)], out, ("import", "stabilize", "remove", "preview"),
                       Models(shots / "actor.removal"))
    results = run_steps(client, takes, on_result=kill_a_busy_worker)
    assert killed, "no worker was busy to kill"
    # a finished step whose result died with the worker is recomputed elsewhere and finds its output current
    assert set(statuses(results).values()) <= {"ok", "skipped"}, [r for r in results if r["status"] not in ("ok", "skipped")]
    for i in range(3):
        assert layer_stack(out / f"shot{i}") == [("take.preview.usdc", "preview"), ("quasistatic.usdc", "remove"),
                                                 ("stabilized.usdc", "stabilize"), ("capture.usdc", "import")]
        leftovers = [p.name for p in (out / f"shot{i}").iterdir() if p.name.startswith(".") and p.name not in (STATE_FILE, ".take.usda.lock")]
        assert not leftovers  # no temporaries (the root's lock file is kept by design)
    assert np.isfinite([r["seconds"] for r in results]).all()
