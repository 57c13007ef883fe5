"""The Rust crate's modules (one per file under src/) use each other without a cycle: a
grep-based check of the `crate::`, `super::` and `self::` paths outside comments and test
modules, resolved to the files they name (issue 22)."""

from __future__ import annotations

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"


def _module(path: Path, src: Path) -> str:
    parts = list(path.relative_to(src).with_suffix("").parts)
    if parts[-1] in ("mod", "lib"):
        parts = parts[:-1]
    return "::".join(["crate", *parts])


def module_graph(src: Path = SRC) -> dict[str, set[str]]:
    """Each module (file) and the other modules its code names."""
    files = {_module(p, src): p for p in src.rglob("*.rs")}
    graph: dict[str, set[str]] = {m: set() for m in files}
    for m, path in files.items():
        text = path.read_text().split("#[cfg(test)]\nmod tests {")[0]
        text = re.sub(r"//.*", "", text)
        for ref in re.findall(r"\b((?:crate|super|self)(?:::\w+)+)", text):
            segs = ref.split("::")
            if segs[0] == "crate":
                base, segs = ["crate"], segs[1:]
            else:
                base = m.split("::")
                while segs and segs[0] in ("super", "self"):
                    if segs[0] == "super":
                        base = base[:-1]
                    segs = segs[1:]
            target = None
            for s in segs:  # the longest prefix that is a module
                if "::".join(base + [s]) not in files:
                    break
                base = base + [s]
                target = "::".join(base)
            if target is None and "::".join(base) in files:
                target = "::".join(base)
            # a module and its own parent or children are one unit (declarations, re-exports)
            if target and target != m and not m.startswith(target + "::") and not target.startswith(m + "::"):
                graph[m].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_module_cycles_in_the_crate() -> None:
    assert cycles(module_graph()) == []


def test_the_check_finds_a_cycle(tmp_path) -> None:
    """The check can fail: two sibling modules that use each other are a cycle."""
    (tmp_path / "a").mkdir()
    (tmp_path / "lib.rs").write_text("pub mod a;\n")
    (tmp_path / "a" / "mod.rs").write_text("mod x;\nmod y;\n")
    (tmp_path / "a" / "x.rs").write_text("use super::y::Y;\n// crate::a::z in a comment is no use\n")
    (tmp_path / "a" / "y.rs").write_text("use crate::a::x::f;\n")
    assert cycles(module_graph(tmp_path)) == [["crate::a::x", "crate::a::y"]]
