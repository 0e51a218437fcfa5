"""Optional dependencies are imported lazily, so the package (and the doctest
collection of every module, pyproject's ``--doctest-modules``) works without them.

do-mpc is the ``bench`` extra: only the do-mpc baseline of ``workbench bench mpc``
needs it. A module-level import anywhere in the package would break ``import`` and
the test collection on an install without the extra. Checked statically (ast), so it
costs nothing and holds whether or not do-mpc is installed here.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "workbench"
#: Distributions of pyproject's optional extras (import names).
OPTIONAL = ("do_mpc", "numba", "osqp")


def _module_level_imports(tree: ast.Module) -> set[str]:
    """Top-level package names imported outside function and class bodies."""
    names: set[str] = set()
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
            continue
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
        stack.extend(ast.iter_child_nodes(node))
    return names


def test_no_module_imports_an_optional_dependency_at_import_time():
    offenders = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        found = _module_level_imports(ast.parse(path.read_text(), str(path))) & set(OPTIONAL)
        if found:
            offenders[str(path.relative_to(PACKAGE.parent))] = sorted(found)
    assert not offenders, offenders


def test_the_check_sees_a_module_level_import():
    # self-check: the walker finds imports at top level and in top-level if/try blocks,
    # and ignores those inside functions
    src = ("import numpy\ntry:\n    import do_mpc\nexcept ImportError:\n    pass\n"
           "def f():\n    import scipy\n")
    assert _module_level_imports(ast.parse(src)) == {"numpy", "do_mpc"}
