"""Running a processor: output checks, the run itself, atomic write, provenance, attach."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import facedyn
from facedyn.errors import UsageError
from facedyn.processors.base import Processor, Request
from facedyn.progress import Progress
from facedyn.usd import layers, schema


def execute(processor: Processor, request: Request, progress: Progress, attach_to: Path | None = None, dry_run: bool = False) -> dict[str, Any]:
    """Run `processor` for `request`; return a JSON-able report of what was (or would be) written."""
    request.params = processor.resolve_params(request.params)
    _check_output(request)
    layers.check_writable(request.output)
    report: dict[str, Any] = {
        "processor": processor.name,
        "inputs": [str(p) for p in request.inputs],
        "output": str(request.output),
        "parameters": {k: _plain(v) for k, v in request.params.items()},
        "frames": list(request.frames) if request.frames else None,
    }
    report["plan"] = processor.check(request)
    if dry_run:
        report["dry_run"] = True
        return report
    started = time.perf_counter()
    result = processor.run(request, progress)
    computed = time.perf_counter() - started
    frames = result.layer.frames
    provenance = schema.Provenance(
        processor=processor.name,
        version=f"facedyn {facedyn.__version__}, {processor.name} {processor.version}",
        parameters=report["parameters"],
        frame_range=(float(frames[0]), float(frames[-1])),
        inputs=result.inputs,
    )
    layers.write_layer(request.output, result.layer, result.timing, provenance, define=result.define)
    if result.root is not None:
        report["root"] = str(_extend_root(result.root, request.output, result.timing))
    if attach_to is not None:
        report["sublayers"] = layers.attach(attach_to, request.output)
        report["root"] = str(attach_to)
    report.update(
        frame_count=int(len(frames)),
        frame_range=[float(frames[0]), float(frames[-1])],
        seconds={"compute": round(computed, 3), "total": round(time.perf_counter() - started, 3)},
        summary=result.summary,
    )
    return report


def _check_output(request: Request) -> None:
    output = request.output.resolve()
    for path in request.inputs:
        if Path(path).resolve() == output:
            raise UsageError(f"{request.output}: the output would overwrite an input; choose another -o")


def _extend_root(root: Path, layer_path: Path, timing) -> Path:
    """Create root with layer_path as its only sublayer, or add it as the weakest of an existing root."""
    if not root.exists():
        return layers.write_take_root(root, [layer_path], timing)
    layers.attach_weakest(root, layer_path)
    return root


def _plain(value: Any) -> Any:
    return str(value) if isinstance(value, Path) else value
