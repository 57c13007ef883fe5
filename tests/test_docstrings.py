"""Every public function and class of the package has a numpydoc docstring: a one-line
summary, then a ``Parameters`` section naming each parameter of its signature as a
``name : type`` line (classes: the ``__init__`` parameters or the dataclass / named-tuple
fields, which result classes may list under ``Attributes`` instead).

Public means listed in a module's ``__all__`` (for the modules of ``pprender.lidar``,
which have none, the names they define without a leading underscore). Objects of the Rust
extension (``pprender._core``: ``Material``, ``BrdfTable``, ``brdf_table``, ``Error``) are
documented in Rust and skipped, as are submodules and constants. Not listed as missing:
``self``/``cls``, ``*args``/``**kwargs`` and private parameters (a leading underscore,
e.g. ``write_chunk``'s ``_store``). An object with no parameters at all needs no
``Parameters`` section (warning classes)."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import re
from types import ModuleType
from typing import Any

import pytest

import pprender
from pprender import _core

# Subpackage modules first, so that each object is checked under the module defining it.
MODULES = [
    "pprender.lidar.sensor",
    "pprender.lidar.scene",
    "pprender.lidar.result",
    "pprender.lidar.dispatch",
    "pprender.lidar.settings",
    "pprender.lidar",
    "pprender.inverse.instrument",
    "pprender.inverse.detector",
    "pprender.inverse.atmosphere",
    "pprender.inverse.database",
    "pprender.inverse.distributed",
    "pprender.inverse.classify",
    "pprender.inverse.fit",
    "pprender.inverse.so3",
    "pprender.inverse.speckle",
    "pprender.inverse.tumble",
    "pprender.mesh",
    "pprender.materials",
    "pprender.models",
    "pprender.plot",
    "pprender.polarimetry",
    "pprender.microfacet",
    "pprender.reference",
    "pprender.validation.seed",
    "pprender.cli",
    "pprender",
]

# A section header: a title line followed by a line of dashes of the same length.
_HEADER = re.compile(r"^(?P<title>[A-Z][A-Za-z ]*)\n-+$", re.M)
# A parameter line at the section's indentation: ``name : type`` (or ``a, b : type``).
_PARAM = re.compile(r"^(?P<names>[*\w][\w, *]*?) : (?P<type>\S.*)$")
_STAR = re.compile(r"^\*{1,2}\w+$")


def _from_core(obj: Any) -> bool:
    return getattr(obj, "__module__", None) == "pprender._core" or any(v is obj for v in vars(_core).values())


def _public(module: ModuleType) -> list[tuple[str, Any]]:
    """(name, object) of the module's public functions and classes defined in pprender."""
    names = getattr(module, "__all__", None)
    if names is None:
        names = [n for n, v in vars(module).items()
                 if not n.startswith("_") and getattr(v, "__module__", None) == module.__name__]
    out = []
    for name in names:
        obj = getattr(module, name)
        if inspect.ismodule(obj) or not (inspect.isfunction(obj) or inspect.isclass(obj)):
            continue
        if not str(getattr(obj, "__module__", "")).startswith("pprender") or _from_core(obj):
            continue
        out.append((name, obj))
    return out


def _owned() -> dict[str, list[tuple[str, Any]]]:
    """Each object once, under the first module of MODULES that lists it."""
    seen: set[int] = set()
    owned: dict[str, list[tuple[str, Any]]] = {}
    for modname in MODULES:
        owned[modname] = []
        for name, obj in _public(importlib.import_module(modname)):
            if id(obj) not in seen:
                seen.add(id(obj))
                owned[modname].append((name, obj))
    return owned


OWNED = _owned()


def _parameters(obj: Any) -> list[str]:
    """The parameter names a docstring must list."""
    if inspect.isclass(obj):
        if dataclasses.is_dataclass(obj):
            return [f.name for f in dataclasses.fields(obj) if f.init]
        if issubclass(obj, tuple) and hasattr(obj, "_fields"):
            return list(obj._fields)
        init = obj.__dict__.get("__init__")
        if init is None:
            init = next((c.__dict__["__init__"] for c in obj.__mro__ if "__init__" in c.__dict__), None)
        if not inspect.isfunction(init):
            return []  # object.__init__ or a C-level one (exceptions and warnings)
        sig = inspect.signature(init)
    else:
        sig = inspect.signature(obj)
    out = []
    for p in sig.parameters.values():
        if p.name in ("self", "cls") or p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD) or p.name.startswith("_"):
            continue
        out.append(p.name)
    return out


def _sections(doc: str) -> dict[str, list[str]]:
    """Section title -> its lines (numpydoc headers), from a cleaned docstring."""
    heads = list(_HEADER.finditer(doc))
    out: dict[str, list[str]] = {}
    for i, h in enumerate(heads):
        end = heads[i + 1].start() if i + 1 < len(heads) else len(doc)
        out[h.group("title").strip()] = doc[h.end():end].strip("\n").splitlines()
    return out


def _documented(lines: list[str]) -> tuple[list[str], list[str]]:
    """Names given as ``name : type`` lines at the section's indentation, and the
    unindented lines that are not of that form."""
    names, bad = [], []
    for line in lines:
        if not line.strip() or line[0].isspace():
            continue
        if _STAR.match(line.rstrip()):
            continue  # ``*args`` / ``**kwargs``: numpydoc gives them no type
        m = _PARAM.match(line.rstrip())
        if m is None:
            bad.append(line.strip())
            continue
        names += [n.strip().lstrip("*") for n in m.group("names").split(",")]
    return names, bad


def _problems(name: str, obj: Any) -> list[str]:
    raw = obj.__doc__
    if not raw or not raw.strip():
        return [f"{name}: no docstring"]
    doc = inspect.cleandoc(raw)
    lines = doc.splitlines()
    out = []
    if not lines[0].strip() or (len(lines) > 1 and lines[1].strip()):
        out.append(f"{name}: the first line is not a one-line summary followed by a blank line")
    want = _parameters(obj)
    if not want:
        return out
    sections = _sections(doc)
    titles = ["Parameters", "Attributes"] if inspect.isclass(obj) else ["Parameters"]
    present = [t for t in titles if t in sections]
    if not present:
        return out + [f"{name}: no {' or '.join(titles)} section (parameters: {', '.join(want)})"]
    documented: list[str] = []
    for t in present:
        names, bad = _documented(sections[t])
        documented += names
        if bad:
            out.append(f"{name}: {t} lines not of the form 'name : type': {bad}")
    missing = [p for p in want if p not in documented]
    if missing:
        out.append(f"{name}: not documented: {', '.join(missing)}")
    if "Parameters" in sections:
        stray = [p for p in _documented(sections["Parameters"])[0] if p not in want]
        if stray and not inspect.isclass(obj):
            out.append(f"{name}: Parameters lists names not in the signature: {', '.join(stray)}")
    return out


def test_objects_found() -> None:
    """The collection is not vacuous: about 100 public objects, each checked once."""
    n = sum(len(v) for v in OWNED.values())
    assert n >= 90, n
    assert any(obj is pprender.Lidar for _, obj in OWNED["pprender.lidar.sensor"])
    assert not any(obj is pprender.Material for v in OWNED.values() for _, obj in v)


@pytest.mark.parametrize("module", MODULES)
def test_numpydoc(module: str) -> None:
    problems = [p for name, obj in OWNED[module] for p in _problems(f"{module}.{name}", obj)]
    assert not problems, f"{len(problems)} docstring problem(s) in {module}:\n  " + "\n  ".join(problems)
