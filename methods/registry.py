"""Where methods come from: the built-ins by name, any other `Method` subclass by its dotted path (Hydra's
`_target_` convention), with one-line errors for a path that cannot be imported or a class that breaks the
interface (methods.method)."""
from __future__ import annotations

import functools
import importlib

from methods.method import Method, MethodError, check_interface

BUILTIN = {
    "bp": "methods.bp.BP",
    "2fsk": "methods.fsk.TwoFSK",
    "3fsk": "methods.fsk3.ThreeFSK",
    "mm2fsk": "methods.mm2fsk.MM2FSK",
    "mm3fsk": "methods.mm3fsk.MM3FSK",
}


def method_class(spec: str | type) -> type[Method]:
    """The Method subclass of a built-in name ('bp', 'mm2fsk', ...), a dotted path ('mypkg.mymethod.MyMethod'),
    or a class. Raises MethodError (one line) when it cannot be imported or breaks the interface."""
    if isinstance(spec, type):
        check_interface(spec)
        return spec
    return _class_of_name(spec)


@functools.lru_cache(maxsize=32)
def _class_of_name(spec: str) -> type[Method]:
    """`method_class` of a name or dotted path, imported and checked once (a fresh-frame call paid ~15 us on the
    H100's host for it; a failure is not cached)."""
    path = BUILTIN.get(spec, spec)
    module_name, _, attr = str(path).rpartition(".")
    if not module_name:
        raise MethodError(f"unknown method {spec!r}; choose one of {', '.join(BUILTIN)} or give a class path "
                          f"(method._target_=mypkg.mymethod.MyMethod)")
    try:
        module = importlib.import_module(module_name)
    except ImportError as err:
        raise MethodError(f"method {spec!r} cannot be imported: {err}") from None
    cls = getattr(module, attr, None)
    if cls is None:
        raise MethodError(f"method {spec!r}: module {module_name} has no {attr!r}")
    check_interface(cls)
    return cls


def make_method(spec: str | type | Method, params: dict | None = None) -> Method:
    """A method instance from a name, path or class and its parameters (an instance passes through unchanged)."""
    if isinstance(spec, Method):
        if params:
            raise MethodError(f"{spec.name}: parameters go to the method's constructor, not beside an instance")
        return spec
    return method_class(spec)(**(params or {}))


def label_of(name: str) -> str:
    """The table label of a built-in method name (the name itself for others)."""
    return method_class(name).label if name in BUILTIN else name
