"""The processor contract: declarations drive the CLI, and every bad option is a usage error naming its flag."""
import numpy as np
import pytest

from facedyn.cli import main
from facedyn.errors import UsageError
from facedyn.processors import registry
from facedyn.processors.base import Parameter, Reads, Writes

BUILT_IN = ("import", "stabilize", "remove", "synthesize", "retarget", "preview", "simulate", "synth", "train-removal", "train-synthesis", "demo", "actor", "evaluate")


def run(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_every_built_in_command_is_a_declared_processor():
    roles = {"import": "captured", "stabilize": "stabilized", "remove": "quasistatic", "synthesize": "synthesized",
             "retarget": "retargeted", "preview": "preview"}
    for name in BUILT_IN:
        processor = registry.load(name)
        assert isinstance(processor.reads, Reads) and isinstance(processor.writes, Writes)
        assert processor.writes.role == roles.get(name)
        assert processor.writes.what == ("layer" if name in roles else "file" if name.startswith("train") or name == "actor" else "folder")
        given = {p.name: p.parse("x") for p in processor.parameters if p.required}
        resolved = processor.resolve_params(given)
        assert set(resolved) == {p.name for p in processor.parameters}
        for param in processor.parameters:
            if param.required:
                with pytest.raises(UsageError, match=param.flag + " is required"):
                    processor.resolve_params({k: v for k, v in given.items() if k != param.name})


@pytest.mark.parametrize("argv, flag", [
    (["train-removal", "c", "-o", "m", "--epochs", "0"], "--epochs"),
    (["train-removal", "c", "-o", "m", "--epochs", "-1"], "--epochs"),
    (["train-removal", "c", "-o", "m", "--subsample", "0"], "--subsample"),
    (["train-removal", "c", "-o", "m", "--subsample", "nan"], "--subsample"),
    (["train-removal", "c", "-o", "m", "--samples", "0"], "--samples"),
    (["train-removal", "c", "-o", "m", "--device", "bogus"], "--device"),
    (["train-removal", "c", "-o", "m", "--seed", "-1"], "--seed"),
    (["train-removal", "c", "-o", "m", "--budget-minutes", "0"], "--budget-minutes"),
    (["train-removal", "c", "-o", "m", "--budget-minutes", "nan"], "--budget-minutes"),
    (["train-synthesis", "c", "-o", "m", "--quasistatic", "truth", "--epochs", "0"], "--epochs"),
    (["train-synthesis", "c", "-o", "m"], "--quasistatic"),
    (["simulate", "-o", "c", "--actor-seed", "-1"], "--actor-seed"),
    (["simulate", "-o", "c", "--noise", "nan"], "--noise"),
    (["simulate", "-o", "c", "--noise", "-1"], "--noise"),
    (["simulate", "-o", "c", "--jobs", "0"], "--jobs"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--reference-fps", "0"], "--reference-fps"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--reference-fps", "nan"], "--reference-fps"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--reference-fps", "-120"], "--reference-fps"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--three-point", "0,0,0"], "--three-point"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--iterations", "0"], "--iterations"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--method", "magic"], "--method"),
    (["preview", "t.usda", "-o", "p.preview.usdc", "--range-mm", "-1"], "--range-mm"),
    (["preview", "t.usda", "-o", "p.preview.usdc", "--range-mm", "nan"], "--range-mm"),
    (["import", "s.usdc", "-o", "c.usdc", "--fps", "inf"], "--fps"),
    (["import", "s.usdc", "-o", "c.usdc", "--fps", "nan"], "--fps"),
    (["import", "s.usdc", "-o", "c.usdc", "--units", "0"], "--units"),
    (["remove", "t.usda", "-o", "q.usdc"], "--model"),
    (["stabilize", "t.usda", "-o", "s.usdc", "--frames", "nan:nan"], "--frames"),
    (["stabilize", "t.usda", "-o", "s.usdc", "-p", "iterations=zero"], "--iterations"),
])
def test_bad_options_are_usage_errors_naming_the_flag(argv, flag, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = run(argv, capsys)
    assert code == 2, err
    assert err.count("\n") == 1 and flag in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("motion", ["platform:0hz", "platform:-5hz", "platform:nanhz", "platform:1e9hz", "platform:4hz:down", "platform:hz:side"])
def test_bad_platform_frequencies_are_usage_errors(motion):
    from facedyn.processors.motion_source import skull_motion

    with pytest.raises(UsageError, match="--skull-motion"):
        skull_motion(motion, 120.0, 10)


def test_a_platform_source_shakes_along_the_axis_named():
    from facedyn.processors.motion_source import skull_motion

    for source, axis in (("platform:4hz:side", 0), ("platform:4hz:forward", 2), ("platform:4hz", 1), ("platform:4hz:up", 1)):
        translate, _, description = skull_motion(source, 120.0, 240)
        assert np.argmax(np.ptp(translate, axis=0)) == axis and description == source


def test_parameter_declarations_check_values():
    p = Parameter("strength", float, 0.5, "how much", minimum=0.0, maximum=1.0)
    assert p.parse("1") == 1.0 and p.validate(0) == 0.0
    for bad in ("2", "-0.1", "nan", "inf", "x"):
        with pytest.raises(UsageError, match="--strength"):
            p.parse(bad)
    required = Parameter("model", str)
    assert required.required
    with pytest.raises(UsageError, match="--model is required"):
        required.validate(None)
    flag = Parameter("fast", bool, False)
    assert flag.parse("yes") is True and flag.parse("off") is False
    with pytest.raises(UsageError, match="--fast"):
        flag.parse("maybe")


def test_help_marks_required_and_prints_each_default_once(capsys):
    with pytest.raises(SystemExit):
        main(["remove", "--help"])
    flat = " ".join(capsys.readouterr().out.split())
    assert ("--model MODEL the removal model file (from train-removal), an actor's linear response (.response, train-synthesis "
            "--response linear), a blend of them (calibrate's removal.blend), or `default`: the shipped person") in flat
    assert "for an actor with neither rig nor session (required)" in flat  # argparse may wrap inside person-independent
    with pytest.raises(SystemExit):
        main(["train-synthesis", "--help"])
    out = capsys.readouterr().out
    assert out.count("(default: 344)") == 1 and "(required)" not in out  # --quasistatic is required unless --response linear
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for name in BUILT_IN:
        assert name in out
    assert "synthesize secondary dynamics for a (new) skull motion" in " ".join(out.split())


def test_json_runs_report_errors_as_json_too(capsys):
    import json

    code, out, err = run(["stabilize", "missing.usda", "-o", "s.usdc", "--json"], capsys)
    assert code == 1 and "missing.usda" in err
    assert json.loads(out) == {"error": err.strip(), "exit_code": 1}
