"""Write docs/results.md from the benchmarks' records in benchmarks/results/*.json.

The results page is generated, never edited: a figure gets onto it by a benchmark run with
``--out benchmarks/results/NAME.json`` (benchmarks/harness.py), or, for figures measured
before the harness, by a record that names its source. Each record says what was run
(command, commit, date, machine, load) and how the figure was obtained (solved or true
skull, rest, mask, which simulator made the test data and the training data, the budget);
a figure that needs simulator truth no capture has is labelled an upper bound.

    python benchmarks/results.py            # rewrite docs/results.md
    python benchmarks/results.py --check    # exit 1 if docs/results.md is not what the records give
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
PAGE = ROOT / "docs" / "results.md"

# The page's sections in reading order: (benchmark, title, what it measures). Benchmarks not
# named here follow in alphabetical order under their own name.
SECTIONS = (
    ("demo", "The demo", "The end-to-end demo on the built-in face, scored against the simulator's truth."),
    ("bench_demo", "The demo's time and disk", "The README's first command as a user runs it: wall time, peak memory and what "
     "it leaves on disk (issue 40: <= 90 s, <= 300 MB)."),
    ("bench_cross_sim", "Removal, synthesis and retargeting on another tissue model",
     "Training on facedyn's spring-membrane simulator, testing on a hyperelastic finite-element layer (another family) "
     "with per-actor parameters, plain captures with a tracker's errors, through import, stabilize --actor, remove, "
     "synthesize and retarget. The closest of these benchmarks to a studio's actor."),
    ("bench_remove_accuracy", "Removal inside the training simulator",
     "Corpus and test takes both from facedyn's simulator, the true skull given: upper bounds for the real path."),
    ("bench_synthesize_accuracy", "Synthesis inside the training simulator",
     "Corpus and test takes both from facedyn's simulator, the true skull given: upper bounds for the real path."),
    ("bench_stabilize_accuracy", "Stabilization accuracy", "Plain captures with tracker-like noise, imported and stabilized, against the true skull."),
    ("bench_stabilize_speed", "Stabilization speed", "Mode pursuit beside the PyTorch reference solver in the same run."),
    ("bench_stabilize_command", "stabilize as a command",
     "The whole `usdfacedyn stabilize` command on the paper's 651 x 1,185 case, start-up, rigidity discovery and writing "
     "included, beside the solve in memory and the PyTorch reference in the same run (issue 40: <= 1.5 s; reference >= 20x "
     "the solve)."),
    ("bench_remove_speed", "Removal speed", "Removal on an ICT-sized mesh, kernels and the whole processor."),
    ("bench_synthesize_speed", "Synthesis speed", "Synthesis on an ICT-sized mesh."),
    ("bench_command_io", "remove and synthesize as commands",
     "The whole command on the ICT rig, 1,000 frames, start-up and USD read and write included, beside its steps timed in "
     "one process (issue 40: >= 1,000 frames/s)."),
    ("bench_long_take", "Long takes", "Each step as its own usdfacedyn process on long takes: time and peak memory."),
    ("bench_import", "Import memory", "Streaming import of long USD caches and OBJ sequences."),
    ("bench_import_skel", "UsdSkel import memory", "A UsdSkel rig's skinning baked one chunk at a time."),
    ("bench_train_memory", "Training memory", "Training through the on-disk feature store."),
    ("bench_train_epoch", "F's epoch on a standard corpus",
     "F with calibrate's flags on the 141-take standard corpus of a 2.7k-point rig: seconds an epoch, peak memory and the "
     "validation loss per epoch (issue 40: <= 25 s an epoch at <= 4 GB)."),
    ("bench_startup", "Start-up", "How long usdfacedyn takes to answer what needs no work, and `inspect MODEL` (issue 40: <= 0.3 s and <= 0.5 s)."),
    ("bench_model_load_memory", "Model load memory",
     "The peak of loading a model file beside the arrays it declares; the libraries' one-time first use kept apart."),
    ("bench_batch", "Farms", "usdfacedyn batch on a local Dask cluster."),
    ("bench_calibrate", "Calibration time",
     "usdfacedyn calibrate on a 70-take session of a 2.7k-point ARKit-named rig, the corpus included (target: 45 minutes "
     "on 2 cores): wall time, each stage's, peak memory, F's measured speed and the epochs the budget gave."),
    ("bench_corpus_protocol", "The corpus on other rigs",
     "The recommended corpus, the Live Link performances included, simulated on a rig as `usdfacedyn simulate` runs it: "
     "takes written and failed (issue 37: it completes on the built-in face, the ICT rig and an ARKit-named rig)."),
    ("testset_static", "The test set's static offsets",
     "How the part of the true dynamics that does not move over a take grows with the motion on the validation actors' "
     "MuJoCo tissues: a floor under any truth-free method's figure on that take (benchmarks/README-testset.md)."),
    ("testset_ceiling", "The linear response's ceiling on the test set's run",
     "What an actor's linear response, fitted as calibrate fits it but on the truth (true skull; the session's true "
     "dynamics, the run itself at half size, or in sample), leaves of the run's moving dynamics on the validation actors' "
     "MuJoCo tissues: whether any fit of that model could reach issue 37's synthesis target there (benchmarks/README-testset.md)."),
    ("testset_blend_ceiling", "Calibrate's choice beside the best blend of its two models",
     "On the validation actors' test takes: the family's F, the actor's linear response, their mean and calibrate's "
     "truth-free choice, beside the blend of F and the response weighed per band with the take's own truth (an upper bound "
     "for any choice of weights): whether the choice or the two models hold removal back (benchmarks/README-testset.md)."),
    ("testset_session_ceiling", "What an actor's session can teach",
     "Models fitted on a validation actor's session with its true dynamics (calibrate's response, unconstrained linear "
     "filters over 0.5 and 1.5 s of skull motion, a network beside the filter), scored on its test takes and on its own "
     "session takes in sample, and the response on the walk re-simulated with a neutral face and at half the motion: "
     "whether a better model of the session, rather than better targets, could reach issue 37's figures "
     "(benchmarks/README-testset.md)."),
    ("testset_spread", "What the spread from the samples loses",
     "A validation actor's true dynamics kept at F's skin samples and spread back to the mesh: by the bi-Laplacian at the "
     "model's samples and at two and four times as many, and with the actor's spread calibrate learns on its stabilized "
     "session: what even a perfect model at the samples would lose (benchmarks/README-testset.md)."),
    ("bench_motion_spectrum", "Skull motion spectra", "Where the skull's acceleration power lies, 6-15 Hz, procedural gaits beside real mocap."),
    ("tests", "The test suite", "The time of the README's test command."),
    ("testset", "Test set",
     "Actors made by a soft-tissue solver facedyn did not write (MuJoCo flex, benchmarks/README-testset.md), scored by "
     "`benchmarks/testset_score.py` (`benchmarks/results/testset/`): the fraction of the true dynamics' RMS a removal leaves "
     "on the face region, solved skull, plain captures with tracker noise; static_share: the part of the truth that does not "
     "move over the take, which no estimate averaging to zero can remove. With `--synthesis`, the transfer take (one test "
     "take's expression under another's skull) scores synthesis, retargeting and delta transfer against its truth (issue 37: "
     "synthesis <= 30 %, retargeting <= 0.5x delta transfer). Validation actors are tuned on; a test actor is "
     "run once per finished change and never used to choose."),
)
TESTSET_COLUMNS = ("take", "frames", "dynamics_rms_mm", "static_share", "do_nothing", "moving_average", "removal")
TRANSFER_FIGURES = ("dynamics_rms_mm", "static_share", "synthesis", "retarget", "delta_transfer", "retarget_to_delta_transfer")
CONTEXT = ("command", "commit", "date", "machine", "load", "note", "source")
NOT_FIGURES = {"id", "benchmark", "case", "obtained", "upper_bound", "table", "notes", *CONTEXT}


class RecordError(ValueError):
    """A results file that cannot be read as records."""


def load_records(folder: Path = RESULTS) -> list[dict]:
    """Every record of every results file, in file order, each checked for its context."""
    records = []
    for path in sorted(folder.glob("*.json")):
        try:
            content = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as error:
            raise RecordError(f"{path}: not a JSON file ({error})") from None
        for index, record in enumerate(content if isinstance(content, list) else [content]):
            missing = [field for field in ("benchmark", "case", "command", "commit", "date", "machine", "load") if not record.get(field)]
            if missing:
                raise RecordError(f"{path}: record {index} lacks {', '.join(missing)}")
            records.append(record)
    return records + testset_records(folder / "testset")


def testset_records(folder: Path) -> list[dict]:
    """testset_score.py's runs (one file each, their own format) as records with a table."""
    records = []
    for path in sorted(folder.glob("*.json")):
        try:
            run = json.loads(path.read_text())
            flags = (f" --removal {run['removal']}" if run.get("removal") else "") + (f" --blend {run['blend']}" if run.get("blend") else "")
            flags += " --no-actor" if run.get("stabilized") == "without --actor" else ""
            flags += f" --synthesis {run['synthesis']}" if run.get("synthesis") else ""
            flags += f" --transfer {run['transfer']}" if run.get("transfer") else ""
            flags += f" --source-actor {run['source_actor']} --source-removal {run['source_removal']}" if run.get("source_actor") else ""
            records.append({
                "benchmark": "testset", "id": f"testset-{path.stem}",
                "case": f"{run['actor']} ({run['split']} actor), removal: {run.get('removal') or 'none'}, stabilized {run.get('stabilized', 'with --actor')}",
                "command": f"python benchmarks/testset_score.py ACTOR_FOLDER{flags}", "commit": run["commit"], "date": run["date"],
                "machine": f"{run['machine']}, {run['cpus']} cores", "load": "not recorded (scores do not depend on it)",
                "obtained": {"skull": "solved (stabilize " + run.get("stabilized", "with --actor") + ")",
                             "rest": "given (the actor made from the actor's rig)" if run.get("stabilized") != "without --actor"
                             else "none (the take's own frame and first frame)",
                             "test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset)",
                             "model": (f"{run['removal']} ({run.get('note') or 'how it was trained: usdfacedyn inspect ' + run['removal']})"
                                       if run.get("removal") else "none: baselines only"),
                             "split": run["split"] + (": tuned on" if run["split"] == "validation" else ": run once, never used to choose")},
                "table": {"columns": list(TESTSET_COLUMNS), "rows": [[take.get(c, "") for c in TESTSET_COLUMNS] for take in run["takes"]]},
                **{f"{case['take']} ({case['expression_of']}'s expression, {case['motion_of']}'s skull): {key}": case[key]
                   for case in run.get("transfers", []) for key in TRANSFER_FIGURES},
            })
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as error:
            raise RecordError(f"{path}: not a testset_score.py run ({error})") from None
    return records


def anchor(record: dict) -> str:
    """The record's link target on the page: its id, else benchmark and case."""
    text = record.get("id") or f"{record['benchmark']}-{record['case']}-{record.get('commit', '')}"
    return re.sub(r"[^a-z0-9]+", "-", str(text).lower()).strip("-")


def cell(value) -> str:
    if isinstance(value, float):
        value = f"{value:g}"
    elif isinstance(value, (list, dict)):
        value = json.dumps(value)
    return str(value).replace("|", "\\|").replace("\n", " ")


def table(columns: list[str], rows: list[list]) -> list[str]:
    return ["| " + " | ".join(cell(c) for c in columns) + " |", "|" + "---|" * len(columns),
            *("| " + " | ".join(cell(v) for v in row) + " |" for row in rows)]


def figures(record: dict) -> dict:
    return {key: value for key, value in record.items() if key not in NOT_FIGURES}


def context_lines(record: dict) -> list[str]:
    lines = [f"- {field}: `{record[field]}`" if field == "command" else f"- {field}: {record[field]}" for field in CONTEXT if record.get(field)]
    obtained = record.get("obtained") or {}
    if obtained:
        lines.append("- how it was obtained:")
        lines += [f"  - {key}: {value}" for key, value in obtained.items()]
    return lines


def render_single(record: dict) -> list[str]:
    """A record with its own table or figures: a heading, its context, its figures."""
    label = " (upper bound)" if record.get("upper_bound") else ""
    lines = [f'<a id="{anchor(record)}"></a>', f"### {record['case']}{label}", "", *context_lines(record), ""]
    if record.get("table"):
        lines += [*table(record["table"]["columns"], record["table"]["rows"]), ""]
    rest = figures(record)
    if rest:
        lines += [*table(["figure", "value"], [[key, value] for key, value in rest.items()]), ""]
    if record.get("notes"):
        lines += [record["notes"], ""]
    return lines


def render_run(records: list[dict]) -> list[str]:
    """Records of one run (one command at one commit) without tables: one table, a row per case."""
    first = records[0]
    shared = {field: first[field] for field in CONTEXT if first.get(field) and all(r.get(field) == first[field] for r in records)}
    varying = [field for field in CONTEXT if field not in shared and any(r.get(field) for r in records)]
    columns = list(dict.fromkeys(key for r in records for key in figures(r)))
    lines = [f'<a id="{anchor({**first, "case": first.get("date", "")})}"></a>',
             f"### `{first['command']}`", "", *context_lines(shared), ""]
    rows = [[r["case"] + (" (upper bound)" if r.get("upper_bound") else ""), *(r.get(f, "") for f in varying),
             *(r.get(c, "") for c in columns), "; ".join(f"{k}: {v}" for k, v in (r.get("obtained") or {}).items())] for r in records]
    with_obtained = any(r.get("obtained") for r in records)
    header = ["case", *varying, *columns] + (["how it was obtained"] if with_obtained else [])
    lines += [*table(header, [row if with_obtained else row[:-1] for row in rows]), ""]
    return lines


def render(records: list[dict]) -> str:
    order = {name: index for index, (name, _, _) in enumerate(SECTIONS)}
    titles = {name: (title, why) for name, title, why in SECTIONS}
    benchmarks = sorted({r["benchmark"] for r in records}, key=lambda name: (order.get(name, len(order)), name))
    lines = ["# Results", "",
             "Generated by `python benchmarks/results.py` from `benchmarks/results/*.json`; do not edit by hand.",
             "Every figure states what was run (command, commit, date, machine, load) and how it was obtained",
             "(solved or true skull, rest, mask, the simulator of the test data and of training, the budget).",
             "A figure that needs the simulator's truth, which no capture has, is labelled an upper bound.",
             "Records marked with a source were measured before the benchmarks wrote records and were",
             "carried over from that source with the commit that recorded them.", ""]
    lines += [f"- [{titles.get(name, (name, ''))[0]}](#section-{anchor({'id': name, 'benchmark': name, 'case': ''})})" for name in benchmarks]
    lines.append("")
    for name in benchmarks:
        title, why = titles.get(name, (name, ""))
        lines += [f'<a id="{"section-" + anchor({"id": name, "benchmark": name, "case": ""})}"></a>', f"## {title}", ""]
        if why:
            lines += [why, ""]
        group: list[dict] = []
        for record in [r for r in records if r["benchmark"] == name] + [None]:
            same_run = record is not None and not record.get("table") and group and all(
                record.get(f) == group[0].get(f) for f in ("command", "commit", "source", "id"))
            if same_run:
                group.append(record)
                continue
            if group:
                lines += render_run(group) if len(group) > 1 else render_single(group[0])
            group = [record] if record is not None else []
    return "\n".join(lines).rstrip() + "\n"


def main() -> int:
    arguments = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    arguments.add_argument("--check", action="store_true", help="only check that docs/results.md is what the records give")
    arguments.add_argument("--results", type=Path, default=RESULTS, help="folder of results files (default: benchmarks/results)")
    arguments.add_argument("--page", type=Path, default=PAGE, help="the page to write (default: docs/results.md)")
    args = arguments.parse_args()
    try:
        page = render(load_records(args.results))
    except RecordError as error:
        print(f"results: error: {error}", file=sys.stderr)
        return 2
    if args.check:
        if not args.page.is_file() or args.page.read_text() != page:
            print(f"results: {args.page} is not what {args.results} gives: run python benchmarks/results.py", file=sys.stderr)
            return 1
        return 0
    temporary = args.page.with_name(f".{args.page.name}.tmp")
    temporary.write_text(page)
    temporary.replace(args.page)
    return 0


if __name__ == "__main__":
    sys.exit(main())
