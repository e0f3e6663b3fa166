"""The import structure of the package (issue 26).

Every module under ``src/varflow`` is parsed with :mod:`ast`; each ``import`` and
``from ... import`` statement, at module level or inside a function, is an edge
from the module to the imported module (relative imports resolved; for ``from X
import y`` the target is ``X.y`` when that is a module of varflow, else ``X``; no
implicit edges to parent packages).  The graph must have no cycle, only
:mod:`varflow.cli` may import the CLI, :mod:`varflow.io` keeps to readers and
writers (no argparse, no CLI), and no module imports a private name (``_x``) of
another package than its own or one of its subpackages.

The docstrings and comments of ``src/varflow`` state the present fact: no issue numbers,
numbered work sessions, tuning-split figures, varflow version numbers or dates; that
history lives in ``benchmarks/HISTORY.md``.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"


def _modules() -> dict[str, tuple[Path, bool]]:
    """``{dotted name: (file, is_package)}`` of every module of varflow."""
    out = {}
    for path in sorted((SRC / "varflow").rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        out[".".join(parts)] = (path, is_package)
    return out


MODULES = _modules()


def _import_nodes(name: str):
    """``(node, target)`` of every import statement of a module (any depth); ``target``
    is the module a ``from ... import`` reads from (relative imports resolved), None
    for a plain ``import``."""
    path, is_package = MODULES[name]
    package = name if is_package else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            yield node, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                yield node, ".".join(base + ([node.module] if node.module else []))
            else:
                yield node, node.module or ""


def _imports(name: str) -> list[tuple[str, int]]:
    """``(imported name, line)`` of every import statement of a module (any depth)."""
    out = []
    for node, target in _import_nodes(name):
        if target is None:
            out += [(a.name, node.lineno) for a in node.names]
        else:
            for a in node.names:
                full = f"{target}.{a.name}"
                out.append((full if full in MODULES else target, node.lineno))
    return out


def _graph() -> dict[str, set[str]]:
    """``module -> imported varflow modules`` (self-imports dropped)."""
    return {name: {t for t, _ in _imports(name) if t in MODULES and t != name}
            for name in MODULES}


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None (iterative DFS)."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    for root in sorted(graph):
        if root in state:
            continue
        stack = [(root, iter(sorted(graph[root])))]
        path = [root]
        state[root] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(child) == 1:
                return path[path.index(child):] + [child]
            elif child not in state:
                state[child] = 1
                stack.append((child, iter(sorted(graph[child]))))
                path.append(child)
    return None


def test_the_module_list_is_complete() -> None:
    for name in ("varflow", "varflow.cli", "varflow.cli._common", "varflow.io.video",
                 "varflow.evaluation.bench.common"):
        assert name in MODULES
    assert MODULES["varflow.cli"][1], "varflow.cli must be a package"


def test_finds_a_planted_cycle() -> None:
    """The checker itself: a cycle is found and printed in order, a DAG passes."""
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_no_import_cycle() -> None:
    cycle = _find_cycle(_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_only_the_cli_imports_the_cli() -> None:
    bad = [f"{name}:{line} imports {target}" for name in MODULES
           if not (name == "varflow.cli" or name.startswith("varflow.cli."))
           for target, line in _imports(name)
           if target == "varflow.cli" or target.startswith("varflow.cli.")]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("name", [n for n in MODULES if n == "varflow.io"
                                  or n.startswith("varflow.io.")])
def test_io_keeps_to_readers_and_writers(name: str) -> None:
    bad = [f"{name}:{line} imports {target}" for target, line in _imports(name)
           if target == "argparse" or target.startswith("argparse.")
           or target == "varflow.cli" or target.startswith("varflow.cli.")]
    assert not bad, "\n".join(bad)


def _private_imports(name: str) -> list[tuple[str, str, int]]:
    """``(module, private name, line)`` of every ``from X import _y`` of a module."""
    return [(target, a.name, node.lineno) for node, target in _import_nodes(name)
            if target is not None for a in node.names
            if a.name.startswith("_") and not a.name.startswith("__")]


def _crosses_packages(name: str, target: str) -> bool:
    """Whether a private name of ``target`` is out of bounds for module ``name``: a module
    may import the private names of its own package and of its subpackages, never of
    another package of varflow."""
    package = name if MODULES[name][1] else name.rpartition(".")[0]
    return (target.startswith("varflow.") or target == "varflow") and target != package \
        and not target.startswith(package + ".")


@pytest.mark.parametrize("name", list(MODULES))
def test_no_private_name_is_imported_across_packages(name: str) -> None:
    """Issues 27 and 46: a package is used through the public names of its modules (the
    multi-frame refinement through the two-frame machinery's public entry points, the
    batch inputs through :func:`varflow.io.sequences.natural_key`, ...), never through
    another package's private names."""
    bad = [f"{name}:{line} imports {target}.{attr}"
           for target, attr, line in _private_imports(name) if _crosses_packages(name, target)]
    assert not bad, "\n".join(bad)


def test_the_package_rule_sees_a_planted_crossing() -> None:
    """The checker itself: a subpackage's privates are the package's own, a sibling's or a
    parent's are another package's."""
    assert not _crosses_packages("varflow.io.video_writer", "varflow.io._atomic")
    assert not _crosses_packages("varflow.evaluation", "varflow.evaluation.bench.common")
    assert _crosses_packages("varflow.batch.inputs", "varflow.io.sequences")
    assert _crosses_packages("varflow.evaluation.bench.twoframe", "varflow.evaluation.datasets")
    assert _crosses_packages("varflow.ops.median", "varflow")
    assert not _crosses_packages("varflow.ops.median", "numpy")


def test_the_private_import_checker_sees_a_planted_import() -> None:
    assert [a for _, a, _ in _private_imports("varflow.ops.median")] == ["_exp_neg_row"]


#: What a docstring or comment of ``src/varflow`` must not hold: the history of a thing
#: (benchmarks/HISTORY.md keeps it).  A version number is three dotted numbers not part
#: of a longer dotted run (so an IP address such as 127.0.0.1 is not one).
_HISTORY_PATTERNS = {
    "issue number": re.compile(r"\b[Ii]ssue\s+\d+"),
    "numbered session": re.compile(r"\b[Ss]essions?\s+\d+"),
    "tuning-split figure": re.compile(r"\btuning\s+split\b"),
    "version number": re.compile(r"(?<!\d)(?<!\d\.)\d+\.\d+\.\d+(?!\.?\d)"),
    "date": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
}

#: Files under src/varflow skipped by the history scan, relative to src/varflow.
def _prose(source: str) -> list[tuple[int, str]]:
    """``(first line, text)`` of every docstring (any bare string statement: module,
    class, function and attribute docstrings) and every block of comments on
    consecutive lines of a module's source; other string literals are code."""
    out = [(node.lineno, node.value.value) for node in ast.walk(ast.parse(source))
           if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
           and isinstance(node.value.value, str)]
    block: list[str] = []
    start = last = 0
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type != tokenize.COMMENT:
            continue
        line = tok.start[0]
        if block and line != last + 1:
            out.append((start, "\n".join(block)))
            block = []
        if not block:
            start = line
        block.append(tok.string.lstrip("#:"))
        last = line
    if block:
        out.append((start, "\n".join(block)))
    return out


def _history_hits(source: str) -> list[tuple[int, str, str]]:
    """``(line, what, matched text)`` of every history pattern in a module's prose."""
    hits = []
    for first, text in _prose(source):
        for what, pattern in _HISTORY_PATTERNS.items():
            for m in pattern.finditer(text):
                hits.append((first + text.count("\n", 0, m.start()), what,
                             " ".join(m.group().split())))
    return sorted(hits)


def _varflow_files() -> dict[str, Path]:
    """``{path relative to src/varflow: file}`` of every module of varflow."""
    root = SRC / "varflow"
    return {path.relative_to(root).as_posix(): path for path in sorted(root.rglob("*.py"))}


def test_src_docstrings_hold_no_history() -> None:
    """Docstrings and comments say what a thing is, its units, its default and why; the
    issue, session, figures, version and date that led to it belong in
    benchmarks/HISTORY.md."""
    bad = [f"src/varflow/{rel}:{line}: {what} {text!r}"
           for rel, path in _varflow_files().items()
           for line, what, text in _history_hits(path.read_text(encoding="utf-8"))]
    assert not bad, "history in docstrings or comments (move it to benchmarks/HISTORY.md):\n" \
        + "\n".join(bad)


def test_the_history_scan_sees_planted_history() -> None:
    """The scanner itself: history in a docstring, an attribute docstring or a comment
    block (also across a line break) is found at its line; code, an IP address and a
    reference number are not."""
    planted = (
        '"""Default 3 (issue 27)."""\n'
        'HOST = "127.0.0.1"  # version 0.7.1, host 127.0.0.1\n'
        'VERSION = "0.8.0"\n'
        '#: Measured on the tuning\n'
        '#: split in session 8.\n'
        'N = 3\n'
        '"""Attribute docstring, 2026-12-04; Technion CS-2008-08."""\n'
        "def f():\n"
        '    """Ends at 1.2.3."""\n'
        '    return "issue 5"\n'
    )
    assert _history_hits(planted) == [
        (1, "issue number", "issue 27"),
        (2, "version number", "0.7.1"),
        (4, "tuning-split figure", "tuning split"),
        (5, "numbered session", "session 8"),
        (7, "date", "2026-12-04"),
        (9, "version number", "1.2.3"),
    ]
