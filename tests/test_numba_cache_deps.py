"""Numba's on-disk cache (``cache=True``) is invalidated per source file: a cached function that
calls a jitted function of *another* file keeps the callee's old machine code after only the
callee's file changed (measured in session 45: the fused loop ``soil/_kernels_loop.py`` kept a
kernel of ``soil/_kernels.py`` that had been changed, on an upgraded checkout).

So every module with cached functions that imports jitted code from another module of ours
declares ``NUMBA_CACHE_DEPENDS``, the digest of the sources it compiles in
(:func:`depends_digest`). A change of such a source fails this test until the digest is renewed,
and renewing it changes the dependent file, which is what makes Numba recompile it.
"""
from __future__ import annotations

import ast
import hashlib
import importlib
import types
from pathlib import Path

import numba.core.registry
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("crashdem", "soil", "bodies", "coupling")


def _modules() -> dict[str, Path]:
    """Every module of our packages, dotted name -> file."""
    out = {}
    for pkg in PACKAGES:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            parts = f.relative_to(ROOT).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = f
    return out


MODULES = _modules()


def _is_jitted(obj) -> bool:
    """A Numba dispatcher, or a module or namespace (``soil._kernels._Dual``) that holds one."""
    if isinstance(obj, numba.core.registry.CPUDispatcher):
        return True
    if isinstance(obj, types.ModuleType):
        return any(isinstance(v, numba.core.registry.CPUDispatcher) for v in vars(obj).values())
    return any(isinstance(v, numba.core.registry.CPUDispatcher)
               for v in getattr(obj, "__dict__", {}).values())


def _jitted_imports(name: str) -> set[str]:
    """The modules of ours from which ``name`` imports jitted code (directly)."""
    tree = ast.parse(MODULES[name].read_text())
    pkg = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    deps = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:          # ``from soil import _kernels``
                    if _is_jitted(importlib.import_module(sub)):
                        deps.add(sub)
                elif base in MODULES:
                    obj = getattr(importlib.import_module(base), alias.name, None)
                    if obj is not None and _is_jitted(obj):
                        deps.add(base)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in MODULES and _is_jitted(importlib.import_module(alias.name)):
                    deps.add(alias.name)
    deps.discard(name)
    return deps


def _closure(name: str) -> list[str]:
    seen: set[str] = set()
    todo = [name]
    while todo:
        for d in _jitted_imports(todo.pop()):
            if d not in seen:
                seen.add(d)
                todo.append(d)
    seen.discard(name)
    return sorted(seen)


def depends_digest(deps: list[str]) -> str:
    """16 hex digits of the sources of ``deps`` (module names, sorted)."""
    h = hashlib.sha256()
    for d in deps:
        h.update(d.encode() + b"\0" + MODULES[d].read_bytes() + b"\0")
    return h.hexdigest()[:16]


CACHED = sorted(n for n, f in MODULES.items() if "cache=True" in f.read_text())


def test_the_cached_modules_are_found():
    # the scan must see the engine's kernels, else the test below checks nothing
    assert {"soil._kernels", "soil._kernels_loop", "coupling._kernels"} <= set(CACHED)
    assert _closure("soil._kernels_loop") == ["soil._kernels", "soil.contact_laws"]
    assert _closure("soil._kernels") == ["soil.contact_laws"]
    assert _closure("coupling._kernels") == []


@pytest.mark.parametrize("name", CACHED)
def test_a_cached_module_declares_the_sources_it_compiles_in(name):
    deps = _closure(name)
    declared = getattr(importlib.import_module(name), "NUMBA_CACHE_DEPENDS", None)
    if not deps:
        assert declared is None, f"{name} compiles in no other module: drop NUMBA_CACHE_DEPENDS"
        return
    want = depends_digest(deps)
    assert declared == want, (
        f"{MODULES[name].relative_to(ROOT)} compiles in jitted code of {', '.join(deps)}, "
        f"which changed: set NUMBA_CACHE_DEPENDS = {want!r} there, so that Numba's per-file "
        "disk cache recompiles it (tests/test_numba_cache_deps.py)")
