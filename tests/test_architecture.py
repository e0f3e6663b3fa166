"""The import structure of the package (issue 26).

Every module under ``src/varflow`` is parsed with :mod:`ast`; each ``import`` and
``from ... import`` statement, at module level or inside a function, is an edge
from the module to the imported module (relative imports resolved; for ``from X
import y`` the target is ``X.y`` when that is a module of varflow, else ``X``; no
implicit edges to parent packages).  The graph must have no cycle, only
:mod:`varflow.cli` may import the CLI, :mod:`varflow.io` keeps to readers and
writers (no argparse, no CLI), and no module imports a private name (``_x``) of
another package than its own or one of its subpackages.
"""

from __future__ import annotations

import ast
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
