"""The documentation stays true: ARCHITECTURE.md's names exist, the results page is generated, links resolve.

Names are checked by parsing facedyn's source (ast), not importing it, so the check is fast
and does not depend on pxr, torch or OpenCL being importable.
"""
from __future__ import annotations

import ast
import importlib.util
import re
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "facedyn"
ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"
FILE_SUFFIXES = {"usda", "usdc", "usd", "py", "json", "md", "png", "exr", "cl", "bvh", "obj", "csv", "txt", "cfg", "toml", "ini", "sh", "removal", "synthesis", "response"}


class SourceIndex:
    """What facedyn's modules define, read from their source."""

    def __init__(self, package: Path):
        self.modules: dict[str, ast.Module] = {}
        for path in sorted(package.rglob("*.py")):
            parts = path.relative_to(package.parent).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            self.modules[name] = ast.parse(path.read_text(), str(path))
        self.defined: set[str] = set()
        self.strings: set[str] = set()
        self.call_literals: dict[str, set[str]] = {}  # callable name -> the string literals its calls pass
        for tree in self.modules.values():
            for node in ast.walk(tree):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                    literals = {a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str)}
                    self.call_literals.setdefault(node.func.id, set()).update(literals)
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    self.defined.add(node.name)
                elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                    self.defined.add(node.id)
                elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                    self.strings.add(node.value)

    @staticmethod
    def members(body: list[ast.stmt]) -> set[str]:
        """Names a module or class body defines (functions, classes, assignments, imports)."""
        names = set()
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                names |= {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                names |= {(a.asname or a.name).split(".")[0] for a in node.names}
            elif isinstance(node, (ast.If, ast.Try)):
                names |= SourceIndex.members(node.body + getattr(node, "orelse", []))
        return names

    def resolves(self, dotted: str) -> bool:
        """Whether `dotted` (with or without the facedyn. prefix, or from a module's own name) exists."""
        parts = dotted.split(".")
        if parts[0] == "facedyn":
            parts = parts[1:]
        starts = [m for m in self.modules if m == "facedyn." + parts[0] or m.endswith("." + parts[0])]
        for start in starts:
            module, rest = start, parts[1:]
            while rest and f"{module}.{rest[0]}" in self.modules:
                module, rest = f"{module}.{rest[0]}", rest[1:]
            if self.attribute(self.modules[module].body, rest):
                return True
        return not parts

    def attribute(self, body: list[ast.stmt], rest: list[str]) -> bool:
        if not rest:
            return True
        if rest[0] not in self.members(body):
            return False
        for node in body:
            if isinstance(node, ast.ClassDef) and node.name == rest[0]:
                return self.attribute(node.body, rest[1:])
        return len(rest) == 1


@lru_cache(maxsize=1)
def index() -> SourceIndex:
    return SourceIndex(PACKAGE)


def schema_names() -> str:
    return "\n".join(p.read_text(errors="replace") for folder in ("schemas", "plugins") for p in (ROOT / folder).rglob("*") if p.is_file())


def spans(text: str) -> list[str]:
    """The text of every inline code span."""
    return re.findall(r"`([^`\n]+)`", text)


def architecture_problems(text: str) -> list[str]:
    """Every module path, dotted name, call and class name ARCHITECTURE.md cites that the code lacks."""
    source, problems = index(), []
    schemas = schema_names()
    for span in spans(text):
        for word in span.replace(",", " ").split():
            word = word.strip("()[]:;")
            if "/" in word and not word.startswith(("../", "<", ".<")) and "<" not in word and "://" not in word:
                if not ((ROOT / word).exists() or (PACKAGE / word).exists()):
                    problems.append(f"path {word!r} does not exist")
        call = re.match(r"^([A-Za-z_]\w*)\((.*)\)", span)
        if call:
            if call.group(1) not in source.defined:
                problems.append(f"{span!r}: {call.group(1)} is defined nowhere in facedyn")
            passed = source.call_literals.get(call.group(1)) or source.strings
            for literal in re.findall(r'"([^"]*)"', call.group(2)):
                if literal not in passed:
                    problems.append(f"{span!r}: no call of {call.group(1)} in facedyn passes {literal!r}")
        for name in re.findall(r"\b[A-Z][a-z0-9]+[A-Z]\w*\b", span):
            if name not in source.defined and name not in schemas:
                problems.append(f"{span!r}: {name} is defined nowhere in facedyn or its schemas")
        if re.fullmatch(r"[A-Z][A-Z0-9_]+", span) and span not in source.defined:
            problems.append(f"constant {span} is defined nowhere in facedyn")
        dotted = re.fullmatch(r"(?:facedyn\.)?[a-z_]\w*(?:\.[A-Za-z_]\w*)+", span.removeprefix("import "))
        entry_point_group = span in source.strings
        if dotted and span.rsplit(".", 1)[-1] not in FILE_SUFFIXES and not entry_point_group and not source.resolves(dotted.group(0)):
            problems.append(f"dotted name {span!r} does not resolve in facedyn")
    tree = re.search(r"```\nfacedyn/\n(.*?)```", text, re.S)
    if tree:
        for line in tree.group(1).splitlines():
            entry = re.match(r"^(\s*)([\w.]+/?)\s", line + " ")
            if entry and (entry.group(2).endswith("/") or entry.group(2).endswith(".py")):
                base = PACKAGE if entry.group(1) else ROOT
                if not (base / entry.group(2)).exists():
                    problems.append(f"package tree: {entry.group(2)} does not exist")
    return problems


def test_architecture_cites_only_what_exists():
    assert architecture_problems(ARCHITECTURE.read_text()) == []


def test_the_check_finds_drift():
    drift = "`Writes(\"model\")` `ModelOutput` `facedyn.usd.nowhere` `facedyn.dynamics.response.no_such_name` `facedyn/nothing.py`\n"
    problems = architecture_problems(drift)
    assert len(problems) == 5, problems


def load_results_module():
    spec = importlib.util.spec_from_file_location("results", ROOT / "benchmarks" / "results.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_results_page_is_generated_from_the_records():
    results = load_results_module()
    page = results.render(results.load_records())
    assert (ROOT / "docs" / "results.md").read_text() == page, "docs/results.md is stale: run python benchmarks/results.py"


def test_results_records_need_their_context(tmp_path):
    results = load_results_module()
    (tmp_path / "bad.json").write_text('[{"benchmark": "b", "case": "c", "command": "x"}]')
    with pytest.raises(results.RecordError, match="lacks commit, date, machine, load"):
        results.load_records(tmp_path)


def markdown_links(path: Path) -> list[tuple[str, str]]:
    return re.findall(r"\[([^\]]+)\]\(([^)\s]+)\)", path.read_text())


DOCUMENTS = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda p: p.name)
def test_relative_links_resolve(document):
    for _, target in markdown_links(document):
        if re.match(r"^[a-z]+:", target):
            continue
        file, _, fragment = target.partition("#")
        path = (document.parent / file).resolve() if file else document
        assert path.exists(), f"{document.name}: link to {target} names no file"
        if fragment:
            anchors = set(re.findall(r'<a id="([^"]+)">', path.read_text()))
            anchors |= {re.sub(r"[^a-z0-9 -]", "", h.lower()).replace(" ", "-") for h in re.findall(r"^#+ (.+)$", path.read_text(), re.M)}
            assert fragment in anchors, f"{document.name}: link to {target}: no such anchor in {path.name}"


def test_readme_is_a_guide_whose_figures_are_links():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) < 250
    outside_links = re.sub(r"\[[^\]]*\]\([^)]*\)", "", text)
    figures = re.findall(r"\d+(?:\.\d+)?\s?%|\d[\d,.]*\s?frames/s", outside_links)
    assert figures == [], f"README quotes figures outside links to docs/results.md: {figures}"
