"""The package's shape: no import loops, pxr only at the edges, algorithms import without USD,
the simulator off the production path, and processors that share code through libraries, not each other."""
import ast
import configparser
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "facedyn"
PXR_ALLOWED = ("facedyn.usd", "facedyn.processors")
# The only modules outside facedyn.sim that import it: the corpus writer (which `simulate` and `calibrate` build
# corpora with), the corpus simulator on Dask and the demo. Whatever reads a corpus, a rig or a take does so without the physics.
SIMULATOR_USERS = {"facedyn.processors.corpus_writer", "facedyn.batch.cluster_corpus", "facedyn.processors.demo"}


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        found[name.removesuffix(".__init__")] = path
    return found


def _imports(path: Path, modules: dict[str, Path]) -> set[str]:
    """Every facedyn module (or pxr) that `path` imports, at module level or inside functions."""
    targets = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            submodules = [f"{node.module}.{alias.name}" for alias in node.names if f"{node.module}.{alias.name}" in modules]
            names = submodules if len(submodules) == len(node.names) else [node.module, *submodules]
        for name in names:
            if name.split(".")[0] == "pxr":
                targets.add("pxr")
                continue
            while name and name not in modules:
                name = name.rpartition(".")[0]
            if name:
                targets.add(name)
    return targets


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(path, modules) - {name, "pxr"} for name, path in modules.items()}


def _in_simulator(name: str) -> bool:
    return name == "facedyn.sim" or name.startswith("facedyn.sim.")


def _processor_modules() -> set[str]:
    """The modules the facedyn.processors entry points (setup.cfg) name: one declared command each."""
    config = configparser.ConfigParser()
    config.read(PACKAGE.parent / "setup.cfg")
    lines = config["options.entry_points"]["facedyn.processors"].strip().splitlines()
    return {line.partition("=")[2].strip().partition(":")[0] for line in lines if line.strip()}


def _declares_a_processor(path: Path) -> bool:
    """Whether the module defines a class deriving from Processor (or from another *Processor class)."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ClassDef):
            bases = [b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases]
            if any(base == "Processor" or base.endswith("Processor") for base in bases):
                return True
    return False


# File names still shared: each package's errors module (the errors of reading files, of takes, and the command
# line's), each named for what it holds in its own package. The list may only shrink.
SHARED_FILE_NAMES = {
    "errors.py": {"facedyn.errors", "facedyn.io.errors", "facedyn.usd.errors"},
}


def test_no_two_modules_share_a_file_name():
    """A module's file name says which one it is (issue 38 found three corpus.py): `corpus_files`, not another `corpus`."""
    by_file: dict[str, set[str]] = {}
    for name, path in _modules().items():
        if path.name != "__init__.py":
            by_file.setdefault(path.name, set()).add(name)
    shared = {file: names for file, names in by_file.items() if len(names) > 1}
    assert shared == SHARED_FILE_NAMES


def test_no_import_loops():
    graph = _graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(name, trail):
        state[name] = 1
        for other in sorted(graph[name]):
            if state.get(other) == 1:
                cycles.append(trail[trail.index(other):] + [other])
            elif other not in state:
                visit(other, trail + [other])
        state[name] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])
    assert cycles == []


def test_pxr_only_in_the_usd_package_and_the_processors():
    modules = _modules()
    users = sorted(name for name, path in modules.items() if "pxr" in _imports(path, modules))
    assert users and all(name.startswith(PXR_ALLOWED) for name in users), users


def test_algorithm_packages_import_without_usd():
    code = ("import sys; sys.modules['pxr'] = None\n"
            "import facedyn, facedyn.performance, facedyn.motion, facedyn.geometry, facedyn.stabilize, facedyn.dynamics.features, "
            "facedyn.io.bvh, facedyn.sim.tissue\nprint('ok')")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr


def test_usd_imports_nothing_from_the_simulator():
    arrows = sorted((name, other) for name, targets in _graph().items() if name.startswith("facedyn.usd")
                    for other in targets if _in_simulator(other))
    assert arrows == []


def test_only_the_corpus_simulator_the_writer_and_the_demo_import_the_simulator():
    users = {name for name, targets in _graph().items() if not _in_simulator(name) and any(map(_in_simulator, targets))}
    assert users <= SIMULATOR_USERS, sorted(users - SIMULATOR_USERS)
    assert "facedyn.processors.demo" in users  # the check sees imports inside functions too


def test_no_processor_module_imports_another():
    """A processor module (registered, or declaring a Processor class) imports none of the others, even inside a function."""
    graph, modules, registered = _graph(), _modules(), _processor_modules()
    assert len(registered) > 10 and all(name in graph for name in registered), sorted(registered - set(graph))
    processors = registered | {name for name, path in modules.items() if name.startswith("facedyn.") and _declares_a_processor(path)}
    arrows = sorted((name, other) for name in processors for other in graph[name] if other in processors and other != name)
    assert arrows == []


def test_the_import_check_sees_imports_inside_functions(tmp_path):
    source = tmp_path / "step.py"
    source.write_text("def run():\n    from facedyn.processors import remove\n    import facedyn.processors.stabilize as s\n"
                      "    from facedyn.processors.model_steps import REMOVES\n")
    assert _imports(source, _modules()) == {"facedyn.processors.remove", "facedyn.processors.stabilize", "facedyn.processors.model_steps"}


def test_library_modules_of_the_processors_declare_no_processor():
    """Shared step code lives in modules that are not commands, so no processor needs another."""
    modules, processors = _modules(), _processor_modules()
    libraries = [name for name in modules if name.startswith("facedyn.processors.") and name not in processors
                 and name != "facedyn.processors.base"]
    assert libraries and [name for name in libraries if _declares_a_processor(modules[name])] == []


ROLE_READERS = {"TakeFrames", "read_take_below", "stage_below"}  # (path, role_name, ...): the take below a role
ROLE_KEYWORDS = ("role", "role_name", "reads")  # Writes(role=), FaceAttributes(role=), Role(reads=), readers' role_name=


def _names_a_role(node: ast.AST) -> bool:
    """A name or attribute that holds a role (role, self.role, written_role, ROLE...)."""
    name = node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""
    return "role" in name.lower() and "roles" not in name.lower()


def _role_values(node: ast.AST) -> list[ast.AST]:
    """The expressions that `node` gives as a role: to a reader, a role keyword, a role variable, or compared with one."""
    if isinstance(node, ast.Call):
        callee = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
        values = [k.value for k in node.keywords if k.arg in ROLE_KEYWORDS]
        if callee in ROLE_READERS and len(node.args) > 1:
            values.append(node.args[1])
        if callee == "Role" and node.args:
            values.append(node.args[0])
        return values
    if isinstance(node, (ast.Assign, ast.AnnAssign)) and node.value is not None:
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        return [node.value] if any(_names_a_role(t) for t in targets) else []
    if isinstance(node, ast.Compare):
        operands = [node.left, *node.comparators]
        return [o for o in operands if not _names_a_role(o)] if any(map(_names_a_role, operands)) else []
    return []


def _bare_role_names(source: str) -> list[int]:
    """The lines of `source` that give a built-in role's name as a string where a role is meant."""
    from facedyn.performance import BUILTIN_ROLES

    role_names = {role.name for role in BUILTIN_ROLES}
    return [node.lineno for node in ast.walk(ast.parse(source)) for v in _role_values(node) for c in ast.walk(v)
            if isinstance(c, ast.Constant) and c.value in role_names]


def test_roles_are_named_by_the_role_tables_constants():
    """A role given to a reader, a Writes, a FaceAttributes or a Role, held in a role variable or compared with one,
    is a constant of facedyn.performance, never a bare string (the table itself defines them)."""
    found = [f"{name}:{line}" for name, path in _modules().items() for line in _bare_role_names(path.read_text())]
    assert found == []


def test_the_role_check_sees_bare_role_names():
    bad = ('TakeFrames(path, "stabilized")\nWrites("layer", role="quasistatic")\nrole: str = "captured"\n'
           'if layer.role in ("preview", "x"): pass\nRole("sculpted", 25, "sculpted layers", reads="synthesized")\n'
           'OffsetStats("synthesized")\nrole = SYNTHESIZED\n')
    assert sorted(_bare_role_names(bad)) == [1, 2, 3, 4, 5]


ALGORITHM_AND_USD_PACKAGES = ("dynamics", "stabilize", "geometry", "kernels", "io", "usd", "preview")


def test_a_packages_public_functions_are_used_beyond_their_module():
    """A module-level function no other module, test, benchmark, example or page names is a
    helper: its name starts with an underscore, so a package's public names are what others use
    (classes are left out: a public function's result types are public with it)."""
    import re

    root = PACKAGE.parent
    texts = {path: path.read_text() for folder in ("facedyn", "tests", "benchmarks", "examples", "docs")
             for path in (root / folder).rglob("*") if path.suffix in (".py", ".md", ".sh") and path.is_file()}
    unused = []
    for package in ALGORITHM_AND_USD_PACKAGES:
        for path in sorted((PACKAGE / package).glob("*.py")):
            for node in ast.parse(path.read_text()).body:
                if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
                    named = re.compile(rf"\b{node.name}\b")
                    if not any(named.search(text) for other, text in texts.items() if other != path):
                        unused.append(f"{path.relative_to(root)}:{node.lineno} {node.name}")
    assert not unused, "public functions nothing else names (make them private):\n" + "\n".join(unused)
