"""The code version of a stored result: the package version and a digest of every module of the compute path.

The modules are found from the import graph, not listed by hand: starting at the app (bench.harness.app, whose
`run` reads the captures, reconstructs and scores every cell), every `import` and `from ... import` statement of
this repository's packages is followed, at any depth and also inside functions (the lazy imports), and so is any
string constant that names one of their modules (the tables behind `importlib.import_module`: methods._EXPORTS,
methods.registry.BUILTIN). A module reached that way can change a stored result, so a change to any of them gives
a new version and the store computes its cells again. Modules the app does not reach (the report, the perf tools,
the tests) do not count. A method outside these packages enters the cell's key by its own file's digest
(bench.harness.app._method_source).

Following the graph parses ~110 sources (0.25 s on a quiet 2-core machine, in every process of a sweep), so the
version is kept in a small cache file (`default_cache_file()`) under a key that digests every source file of the
packages (their paths and bytes: whatever the graph could reach or newly reach): any edit, new or removed file gives
a new key and the graph is followed again. A cache that cannot be read or written is skipped.
"""
from __future__ import annotations

import ast
import functools
import hashlib
import json
import re
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from bench.cachedir import default_cache_dir

PACKAGE_ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("bench", "methods", "metrics")
COMPUTE_ENTRY = "bench.harness.app"
CACHE_ENTRIES = 16       # versions of the tree kept (branches switched back and forth)
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


def package_version(root: Path = PACKAGE_ROOT) -> str:
    """The installed package's version; from a checkout that was never installed (sources on PYTHONPATH), the
    version its pyproject.toml declares, or "0+unknown" without one."""
    try:
        return version("mm2fsk-bench")
    except PackageNotFoundError:
        import tomllib

        try:
            return str(tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"])
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "0+unknown"


def _compute_version(root: Path = PACKAGE_ROOT) -> str:
    digest = hashlib.sha256()
    for path in sorted(compute_modules(root=root).values()):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return f"{package_version(root)}+{digest.hexdigest()[:12]}"


def sources_key(root: Path = PACKAGE_ROOT) -> str:
    """sha256 of every .py file of the packages under `root` (relative path and bytes) and the package version: what
    `compute_modules` and so the code version can depend on."""
    digest = hashlib.sha256(package_version(root).encode() + b"\0")
    for path in sorted(p for package in PACKAGES for p in (root / package).rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def default_cache_file() -> Path | None:
    """The cache's file: code_version.json in `default_cache_dir()`."""
    folder = default_cache_dir()
    return None if folder is None else folder / "code_version.json"


def cached_version(root: Path = PACKAGE_ROOT, cache_file: Path | None = None) -> str:
    """`_compute_version`, read from `cache_file` (default: `default_cache_file()`) when it holds this tree's
    `sources_key`, else computed and kept."""
    cache_file = cache_file or default_cache_file()
    if cache_file is None:
        return _compute_version(root)
    key = sources_key(root)
    try:
        kept = json.loads(cache_file.read_text())
        if not isinstance(kept, dict):
            kept = {}
    except (OSError, ValueError):
        kept = {}
    if isinstance(kept.get(key), str):
        return kept[key]
    found = _compute_version(root)
    kept = {k: v for k, v in kept.items() if k != key and isinstance(v, str)}
    kept = dict(list(kept.items())[-(CACHE_ENTRIES - 1):] + [(key, found)])
    try:
        from bench.harness import atomic

        cache_file.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(cache_file, json.dumps(kept).encode())
    except OSError:
        pass                # a read-only home: computed again next time
    return found


@functools.cache
def code_version() -> str:
    """`<package version>+<sha256 prefix of the compute path's sources>`; found once per process (the code a process
    runs is what it imported), from the cache file where the sources are unchanged (module doc)."""
    return cached_version()
