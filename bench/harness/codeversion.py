"""The code version of a stored result: the package version and a digest of every module of the compute path.

The modules are found from the import graph, not listed by hand: starting at the app (bench.harness.app, whose
`run` reads the captures, reconstructs and scores every cell), every `import` and `from ... import` statement of
this repository's packages is followed, at any depth and also inside functions (the lazy imports), and so is any
string constant that names one of their modules (the tables behind `importlib.import_module`: methods._EXPORTS,
methods.registry.BUILTIN). A module reached that way can change a stored result, so a change to any of them gives
a new version and the store computes its cells again. Modules the app does not reach (the report, the perf tools,
the tests) do not count. A method outside these packages enters the cell's key by its own file's digest
(bench.harness.app._method_source).
"""
from __future__ import annotations

import ast
import functools
import hashlib
import re
from importlib.metadata import version
from pathlib import Path

PACKAGE_ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("bench", "methods", "metrics")
COMPUTE_ENTRY = "bench.harness.app"
_MODULE_NAME = re.compile(rf"(?:{'|'.join(PACKAGES)})(?:\.\w+)+")


def module_file(name: str, root: Path = PACKAGE_ROOT) -> Path | None:
    """The source file of module or package `name` under `root`, or None where it is not one of ours."""
    if name.split(".")[0] not in PACKAGES:
        return None
    base = root.joinpath(*name.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _imported_names(path: Path, module: str) -> set[str]:
    """Dotted names a module's source imports (absolute, relative resolved; `from a import b` gives a and a.b) or
    names in string constants."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    names = set()
    for node in ast.walk(ast.parse(path.read_bytes(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parent = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parent + ([base] if base else []))
            names.add(base)
            names.update(f"{base}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and _MODULE_NAME.fullmatch(node.value):
            names.add(node.value)
            names.add(node.value.rpartition(".")[0])        # "methods.bp.BP": the module of a class path
    return names


def compute_modules(entry: str = COMPUTE_ENTRY, root: Path = PACKAGE_ROOT) -> dict[str, Path]:
    """Every module of ours reachable from `entry` through imports (module doc), with its parent packages (their
    `__init__` runs first): {dotted name: source file}."""
    found: dict[str, Path] = {}
    todo = [entry]
    while todo:
        name = todo.pop()
        parts = name.split(".")
        for depth in range(1, len(parts) + 1):           # a module's packages are imported before it
            prefix = ".".join(parts[:depth])
            path = module_file(prefix, root)
            if path is not None and prefix not in found:
                found[prefix] = path
                todo.extend(_imported_names(path, prefix))
    return found


@functools.cache
def code_version() -> str:
    """`<package version>+<sha256 prefix of the compute path's sources>`; found and hashed once per process (the
    code a process runs is what it imported)."""
    digest = hashlib.sha256()
    for path in sorted(compute_modules().values()):
        digest.update(path.relative_to(PACKAGE_ROOT).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return f"{version('mm2fsk-bench')}+{digest.hexdigest()[:12]}"
