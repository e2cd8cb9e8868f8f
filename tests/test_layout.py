"""The package's layout rules, checked on its source (the layers and cycles: import-linter).

- no file in ``bench_sim/`` over 500 lines, no function over 80 lines;
- no two modules or packages with the same name;
- imports between bench_sim's own modules only at the top of a module (an import inside a
  function hides a dependency from import-linter's graph and from the reader);
- ``bench_sim.cli`` imports none of the heavy libraries (Mitsuba/Dr.Jit, Dask, matplotlib,
  xarray, zarr), so ``bench-sim --help`` stays fast: they are imported where they are used.
"""

from __future__ import annotations

import ast
import importlib
import importlib.util
import json
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "bench_sim"
SOURCES = sorted(PACKAGE.rglob("*.py"))
MAX_FILE_LINES = 500
MAX_FUNCTION_LINES = 80
HEAVY = ("mitsuba", "drjit", "dask", "distributed", "matplotlib", "xarray", "zarr")


def _rel(path: Path) -> str:
    return str(path.relative_to(PACKAGE.parent))


def _functions(tree: ast.AST) -> list[ast.FunctionDef | ast.AsyncFunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_file_length(path: Path) -> None:
    lines = len(path.read_text().splitlines())
    assert lines <= MAX_FILE_LINES, f"{_rel(path)}: {lines} lines (at most {MAX_FILE_LINES})"


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_function_length(path: Path) -> None:
    long = [
        f"{f.name} ({f.end_lineno - f.lineno + 1} lines, line {f.lineno})"
        for f in _functions(ast.parse(path.read_text()))
        if f.end_lineno is not None and f.end_lineno - f.lineno + 1 > MAX_FUNCTION_LINES
    ]
    assert not long, f"{_rel(path)}: functions over {MAX_FUNCTION_LINES} lines: {', '.join(long)}"


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_own_imports_at_the_top(path: Path) -> None:
    inner = []
    for func in _functions(ast.parse(path.read_text())):
        for node in ast.walk(func):
            if isinstance(node, ast.ImportFrom) and (
                node.level or (node.module or "").startswith("bench_sim")
            ):
                inner.append(f"line {node.lineno} in {func.name}")
            elif isinstance(node, ast.Import) and any(a.name.startswith("bench_sim") for a in node.names):
                inner.append(f"line {node.lineno} in {func.name}")
    assert not inner, f"{_rel(path)}: bench_sim imported inside a function: {', '.join(inner)}"


#: the roles of a workflow package's modules (``workflows/sweep/spec.py``, ``workflows/dataset/spec.py``):
#: the same name in each workflow package, and nowhere else
WORKFLOW_ROLES = {"spec", "run", "report"}
#: public modules at the top of the package that present the workflow package of the same name
#: (``bench_sim.dataset``: ``from bench_sim.dataset import iter_batches``), and nothing else
PUBLIC_FACADES = {"dataset.py": "workflows/dataset"}


def test_module_names_unique() -> None:
    names: Counter[str] = Counter()
    for p in SOURCES:
        if p.name == "__main__.py" or p == PACKAGE / "__init__.py":
            continue
        if p.parent == PACKAGE and p.name in PUBLIC_FACADES:
            assert (PACKAGE / PUBLIC_FACADES[p.name] / "__init__.py").is_file(), p
            continue
        name = p.parent.name if p.name == "__init__.py" else p.stem
        in_workflow_package = p.parent.parent.name == "workflows" and p.name != "__init__.py"
        if not (in_workflow_package and name in WORKFLOW_ROLES):
            names[name] += 1
    twice = sorted(n for n, c in names.items() if c > 1)
    assert not twice, f"module or package names used more than once in bench_sim/: {twice}"


def test_cli_import_is_light() -> None:
    code = (
        "import sys, bench_sim.cli\n"
        f"print(' '.join(sorted(m for m in {HEAVY!r} if m in sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "", f"importing bench_sim.cli loads heavy modules: {out.strip()}"


def test_architecture_doc_matches_the_tree() -> None:
    """docs/architecture.md names every folder of bench_sim/, and every path it names exists."""
    doc = (PACKAGE.parent / "docs" / "architecture.md").read_text()
    folders = sorted(
        str(p.relative_to(PACKAGE.parent)) + "/"
        for p in PACKAGE.rglob("*")
        if p.is_dir() and p.name != "__pycache__" and "scenes" not in p.relative_to(PACKAGE).parts[1:]
        and p.parent.name != "scenes"
    )
    missing = [f for f in folders if f"`{f}`" not in doc]
    assert not missing, f"docs/architecture.md does not describe: {missing}"
    named = set(re.findall(r"`(bench_sim/[\w/.]*)`", doc))
    gone = sorted(n for n in named if not (PACKAGE.parent / n).exists())
    assert not gone, f"docs/architecture.md names paths that do not exist: {gone}"


#: the program's entry module: importing it starts the command line's process set-up (its signal
#: handlers become the importing process's own), so it is read, never imported, here
PROGRAM = "bench_sim.__main__"


def _program_has(names: list[str]) -> bool:
    """Whether :data:`PROGRAM` defines ``names[0]`` at its top level (read from its source)."""
    spec = importlib.util.find_spec(PROGRAM)
    assert spec is not None and spec.origin is not None
    tree = ast.parse(Path(spec.origin).read_text())
    defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
    defined |= {t.id for n in tree.body if isinstance(n, ast.Assign)
                for t in n.targets if isinstance(t, ast.Name)}
    return len(names) <= 1 and (not names or names[0] in defined)


def _resolves(dotted: str) -> bool:
    if dotted == PROGRAM or dotted.startswith(PROGRAM + "."):
        return _program_has(dotted[len(PROGRAM) + 1:].split(".") if dotted != PROGRAM else [])
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        try:
            for name in parts[i:]:
                obj = getattr(obj, name)
        except AttributeError:
            return False
        return True
    return False


#: endings of the file names the docs quote (``manifest.csv``, ``paper_rig.toml``)
FILE_SUFFIXES = {"py", "toml", "md", "json", "csv", "png", "zarr", "nc", "tiff", "tif", "exr", "npy", "npz",
                 "parquet", "txt", "xml", "sh", "tex"}
#: libraries whose dotted names the docs quote (checked when installed)
LIBRARIES = {"numpy", "pandas", "xarray", "torch", "dask", "os", "scipy", "zarr", "mitsuba", "drjit",
             "ast", "inspect"}
#: dotted names in the docs that are notation, not code or config (EMVA 1288's symbols)
NOTATION = {"mu_e.sat", "mu_p.sat", "mu_y.dark", "sigma_y.dark"}  # EMVA 1288 symbols
_SPAN = re.compile(r"`([^`\n]+)`")
_FENCE = re.compile(r"^```.*?^```", re.M | re.S)
_DOTTED = re.compile(r"(?<![\w./-])([A-Za-z_]\w*(?:\.[A-Za-z_]\w*)+)(?![\w/])")


def _config_names() -> set[str]:
    from bench_sim.config.catalogue import config_keys

    keys = {k.key for k in config_keys()}
    return keys | {".".join(k.split(".")[:i]) for k in keys for i in range(1, k.count(".") + 1)}


def _effect_key_ok(name: str) -> bool:
    """``sensor.effects.<name>.<key>``: a key of some sensor effect (``bench-sim config keys sensor``)."""
    from bench_sim.workflows.config_cmd import effect_keys

    parts = name.split(".")
    if len(parts) != 4 or parts[:2] != ["sensor", "effects"]:
        return False
    return parts[3] in {k.key.rsplit(".", 1)[1] for k in effect_keys()}


def _dotted_name_ok(name: str, config: set[str]) -> bool:
    """A dotted name of the docs, with or without ``bench_sim.``: a module or attribute of bench_sim
    (``workflows.dataset.splits.split_of`` as well), a config key or table, a file name, a
    library's name, or notation."""
    if name.startswith("bench_sim."):
        return _resolves(name)
    first, last = name.split(".")[0], name.rsplit(".", 1)[1]
    if last.lower() in FILE_SUFFIXES or name in config or name in NOTATION or _effect_key_ok(name):
        return True
    if first in LIBRARIES:
        return _resolves(name) or importlib.util.find_spec(first) is None
    return _resolves(f"bench_sim.{name}")


@pytest.mark.parametrize("name, ok", [
    ("experiments.execution.task_seed_sequence", False),  # a module that no longer exists
    ("runtime.execution.task_seed_sequence", True),
    ("bench_sim.runtime.execution.no_such_name", False),
    ("bench_sim.__main__.main", True),  # the program: read, not imported
    ("bench_sim.__main__.no_such_name", False),
    ("lights.strong.irradiance_w_m2", True),
    ("lights.strong.flux", False),
    ("sensor.effects.knee.compression", True),  # a key of a sensor effect
    ("sensor.effects.knee.flux", False),
    ("manifest.csv", True),
    ("numpy.random.no_such_name", False),
])
def test_dotted_names_are_judged(name: str, ok: bool) -> None:
    assert _dotted_name_ok(name, _config_names()) == ok


def test_documented_names_resolve() -> None:
    """Every ``bench_sim.x.y`` that the README and docs/ name is a module or attribute that exists,
    and so is every dotted name in their code spans without the prefix (``experiments.execution.x``
    named a module that no longer exists): a config key, a file name or a library's name
    otherwise."""
    root = PACKAGE.parent
    docs = [root / "README.md", *sorted((root / "docs").rglob("*.md"))]
    bad = sorted(
        f"{d.relative_to(root)}: {name}"
        for d in docs
        for name in set(re.findall(r"\bbench_sim(?:\.[A-Za-z_]\w*)+", d.read_text()))
        if not _resolves(name)
    )
    assert not bad, f"documented names that do not exist: {bad}"
    config = _config_names()
    spans = {d: [n for span in _SPAN.findall(_FENCE.sub("", d.read_text())) for n in _DOTTED.findall(span)]
             for d in docs}
    bad = sorted({f"{d.relative_to(root)}: {n}" for d, names in spans.items() for n in names
                  if not _dotted_name_ok(n, config)})
    assert not bad, f"dotted names in the docs that are no module, attribute, config key or file: {bad}"
    paths = sorted(
        f"{d.relative_to(root)}: {p}"
        for d in docs
        for p in set(re.findall(r"(?<![\w/.~])bench_sim/[\w/]*[\w](?:\.py)?", d.read_text()))
        if not (root / p).exists()
    )
    assert not paths, f"documented paths that do not exist: {paths}"


def test_public_api() -> None:
    """``bench_sim.__all__`` names the public API, each name resolves, and the package alone is light."""
    code = (
        "import sys, bench_sim\n"
        "light = not any(m.startswith('bench_sim.') for m in sys.modules)\n"
        "names = {n: getattr(bench_sim, n) for n in bench_sim.__all__}\n"
        "import json\n"
        "api = [callable(names['simulate']), hasattr(names['dataset'], 'open')]\n"
        "print(json.dumps([light, sorted(names), *api]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    public = ["__version__", "calibrate", "dataset", "design", "load_config", "run_pass", "simulate"]
    assert json.loads(out) == [True, public, True, True]
