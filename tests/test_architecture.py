"""The layering rules of docs/architecture.md, read from the source (no module is imported).

util ← theory ← reduced ← fe ← app, each importing only from the layers left of it; ``geometry``
imports nothing from fem_squeal; ``reduced`` imports no dolfinx/PETSc/UFL; no import cycles between
modules; an import inside a function body is allowed only with a comment naming the heavy optional
import it defers (``# heavy: ...`` on the line or the line before); no private module of another
package is imported, and nothing is compiled at run time (the kernels are built with the package).

The tests themselves: every test file lives in ``tests/unit/<layer>``, ``tests/integration`` or
``tests/mpi`` (this file alone at the top), file names are unique, and no test imports ``conftest``:
shared code is a fixture of a ``conftest.py`` or a helper of ``tests/support``."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ["util", "theory", "reduced", "fe", "app"]      # each may import the ones before it
FE_STACK = {"dolfinx", "petsc4py", "slepc4py", "ufl", "basix", "ffcx", "gmsh"}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in ("fem_squeal", "geometry"):
        for p in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(p.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = p
    return out


MODULES = _modules()


def _imports(path: Path) -> list[tuple[str, int, bool]]:
    """(imported module, line, inside a function) of every import in ``path``; ``from a import b``
    yields ``a.b`` when that is a module of the package, else ``a``."""
    tree = ast.parse(path.read_text())
    in_function: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            in_function |= {id(n) for n in ast.walk(node)} - {id(node)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno, id(node) in in_function) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            for a in node.names:
                full = f"{node.module}.{a.name}"
                out.append((full if full in MODULES else node.module, node.lineno, id(node) in in_function))
    return out


def _layer(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] == "geometry":
        return "geometry"
    if parts[0] == "fem_squeal" and len(parts) > 1 and parts[1] in LAYERS:
        return parts[1]
    return None


def test_every_package_module_is_in_a_layer():
    """A newcomer finds each module in its layer: at the top of fem_squeal only the package, its
    entry points and the public re-exports."""
    top = {m for m in MODULES if m.startswith("fem_squeal") and _layer(m) is None}
    assert top == {"fem_squeal", "fem_squeal.__main__", "fem_squeal.cli"}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_only_downward(module):
    layer = _layer(module)
    errors = []
    for name, line, _ in _imports(MODULES[module]):
        root = name.split(".")[0]
        target = _layer(name)
        where = f"{MODULES[module].relative_to(ROOT)}:{line} imports {name}"
        if layer == "geometry" and root == "fem_squeal":
            errors.append(f"{where}: geometry imports nothing from fem_squeal")
        if layer in LAYERS and target in LAYERS and LAYERS.index(target) > LAYERS.index(layer):
            errors.append(f"{where}: layer {layer} may not import the higher layer {target}")
        if layer in ("util", "theory") and target == "geometry":
            errors.append(f"{where}: {layer} imports no geometry")
        if layer in ("util", "theory", "reduced") and root in FE_STACK:
            errors.append(f"{where}: {layer} is NumPy/SciPy only")
    assert not errors, "\n".join(errors)


#: fe modules that are NumPy, SciPy and mpi4py only, with everything of the package they import (issue 34:
#: the block Krylov methods and the blocks' algebra, testable and reusable without the FE stack)
FE_STACK_FREE = ("fem_squeal.fe.eigen.block_krylov", "fem_squeal.fe.row_blocks")


@pytest.mark.parametrize("module", FE_STACK_FREE)
def test_block_krylov_is_numpy_and_mpi4py_only(module):
    seen, todo, errors = set(), [module], []
    while todo:
        m = todo.pop()
        if m in seen:
            continue
        seen.add(m)
        for name, line, _ in _imports(MODULES[m]):
            if name.split(".")[0] in FE_STACK:
                errors.append(f"{MODULES[m].relative_to(ROOT)}:{line} imports {name}")
            elif name in MODULES and name != "fem_squeal" and not name.endswith(".__init__"):
                todo.append(name)
    assert not errors, f"{module} (with what it imports) is NumPy/SciPy/mpi4py only:\n" + "\n".join(errors)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_function_body_imports_name_their_reason(module):
    """Imports go at the top; one inside a function must defer a heavy optional import and say which."""
    lines = MODULES[module].read_text().splitlines()
    bad = [f"{MODULES[module].relative_to(ROOT)}:{line}: {name}"
           for name, line, inside in _imports(MODULES[module])
           if inside and "# heavy" not in lines[line - 1] and "# heavy" not in lines[line - 2]]
    assert not bad, "imports inside functions without a '# heavy: <what>' comment:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph = {m: {n for n, _, _ in _imports(p) if n in MODULES and n != m} for m, p in MODULES.items()}
    # a module importing a submodule imports its package too; a package importing its own submodules
    # (re-exports in __init__) is not a cycle of the layering
    state: dict[str, int] = {}
    cycles = []

    def visit(m: str, stack: list[str]) -> None:
        state[m] = 1
        for n in sorted(graph[m]):
            if n.startswith(m + "."):
                continue
            if state.get(n) == 1:
                cycles.append(" -> ".join(stack[stack.index(n):] + [n]))
            elif n not in state:
                visit(n, stack + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_rules_are_checked_on_a_bad_example(tmp_path):
    """The checker itself: a geometry module importing fem_squeal and a reduced module importing
    dolfinx inside a function without a reason are both caught."""
    p = tmp_path / "m.py"
    p.write_text("import numpy\n\ndef f():\n    from dolfinx import fem\n    return fem\n")
    assert _imports(p) == [("numpy", 1, False), ("dolfinx", 4, True)]
    p.write_text("def f():\n    # heavy: dolfinx (the FE stack)\n    from dolfinx import fem\n")
    lines = p.read_text().splitlines()
    name, line, inside = _imports(p)[0]
    assert inside and "# heavy" in lines[line - 2]


#: private parts of other packages still used, each a workaround of a bug of the Debian version, with the
#: module that uses it: (module, private name) -> the bug
PRIVATE_ALLOWED = {
    ("geometry.mesh_file", "meshio._helpers"): "meshio 5.0's read() calls sys.exit on a ReadError; its "
                                                "reader table raises instead",
    ("geometry.mesh_file", "meshio._mesh"): "meshio 5.0 reads wedge15/pyramid13 but lacks them in its "
                                            "table of cell dimensions (and does not export it)",
    ("fem_squeal.app.convert", "meshio.nastran._nastran"): "meshio 5.0's Nastran float writer fails on "
                                                           "negative numbers",
}


def _private_imports(path: Path) -> list[tuple[str, int]]:
    """(name, line) of imports of another package's private parts: a module path component, or a
    name imported from it, starting with ``_``."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names if a.name.startswith("_")]
        else:
            continue
        out += [(n, node.lineno) for n in names if n.split(".")[0] not in ("fem_squeal", "geometry", "__future__")
                and any(part.startswith("_") for part in n.split("."))]
    return out


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_private_module_of_another_package(module):
    """``_cffi_backend``-like imports tie the code to another package's internals: only public modules
    of other packages, but for the listed workarounds of known bugs (:data:`PRIVATE_ALLOWED`)."""
    path = MODULES[module]
    bad = [f"{path.relative_to(ROOT)}:{line}: {name}" for name, line in _private_imports(path)
           if (module, name) not in PRIVATE_ALLOWED]
    assert not bad, "imports of private modules:\n" + "\n".join(bad)


def test_the_private_import_workarounds_are_still_there():
    """An allowed private import that is gone must leave the list (so the list cannot hide new ones)."""
    used = {(m, n) for m in MODULES for n, _ in _private_imports(MODULES[m])}
    assert set(PRIVATE_ALLOWED) <= used


COMPILERS = {"cc", "gcc", "g++", "clang", "c++", "icc", "cython", "cythonize"}


@pytest.mark.parametrize("module", sorted(MODULES))
def test_nothing_is_compiled_at_run_time(module):
    """No module runs a C compiler or builds an extension (the kernels are built with the package by
    setup.py, :mod:`fem_squeal.fe.kernels`): no subprocess outside the command line's ``bench``
    launcher, no compiler named in a string, no setuptools/distutils/cffi build at run time."""
    path = MODULES[module]
    tree = ast.parse(path.read_text())
    where = str(path.relative_to(ROOT))
    bad = [f"{where}:{line}: imports {name}" for name, line, _ in _imports(path)
           if name.split(".")[0] in ("setuptools", "distutils", "Cython", "pyximport")
           or (name == "subprocess" and module != "fem_squeal.app.cli")]
    bad += [f"{where}:{node.lineno}: names the compiler {node.value!r}" for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in COMPILERS]
    bad += [f"{where}:{node.lineno}: {node.attr}" for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and node.attr in ("compile", "set_source", "verify")
            and isinstance(node.value, ast.Name) and node.value.id in ("ffi", "_ffi", "FFI")]
    assert not bad, "run-time compilation:\n" + "\n".join(bad)


def test_the_checks_catch_a_runtime_compiler_and_a_private_import(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("import _cffi_backend\nfrom meshio import _mesh\nimport subprocess\n"
                 "subprocess.run(['gcc', '-shared'])\n")
    names = [n for n, _, _ in _imports(p)]
    assert "subprocess" in names
    assert [n for n, _ in _private_imports(p)] == ["_cffi_backend", "meshio._mesh"]
    consts = [n.value for n in ast.walk(ast.parse(p.read_text())) if isinstance(n, ast.Constant)]
    assert "gcc" in consts and "gcc" in COMPILERS


TESTS = ROOT / "tests"
TEST_FOLDERS = {f"unit/{layer}" for layer in ("geometry", "util", "reduced", "fe", "app")} | {"integration", "mpi"}


def _test_files() -> list[Path]:
    return sorted(p for p in TESTS.rglob("test_*.py") if p != Path(__file__).resolve())


def _imports_conftest(path: Path) -> list[int]:
    """Lines of ``path`` that import ``conftest`` (``import conftest``, ``from conftest import ...``)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "conftest" for a in node.names):
            out.append(node.lineno)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "conftest":
            out.append(node.lineno)
    return out


def test_every_test_file_lives_in_a_layer_integration_or_mpi():
    """A newcomer finds a test beside its subject: tests/unit/<layer>, tests/integration, tests/mpi;
    at the top of tests/ only the fixtures (conftest.py), this file, support/ and data/."""
    assert len(_test_files()) > 40
    bad = [str(p.relative_to(TESTS)) for p in _test_files()
           if p.parent.relative_to(TESTS).as_posix() not in TEST_FOLDERS]
    assert not bad, f"test files outside {sorted(TEST_FOLDERS)}: {bad}"
    assert {p.name for p in TESTS.glob("*.py")} == {"conftest.py", "test_architecture.py"}
    assert {p.name for p in TESTS.iterdir() if p.is_dir() and not p.name.startswith((".", "__"))} == \
        {"unit", "integration", "mpi", "support", "data"}


def test_test_file_names_are_unique():
    """pytest imports test files without packages by their base name (and the two-rank children find a
    test module by it): two files of one name in two folders would collide."""
    names = [p.name for p in _test_files()]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})


def test_no_test_imports_conftest():
    """Shared code is a fixture (conftest.py) or a helper of tests/support, never an import of a conftest."""
    bad = [f"{p.relative_to(ROOT)}:{line}" for p in sorted(TESTS.rglob("*.py")) for line in _imports_conftest(p)]
    assert not bad, "imports of conftest:\n" + "\n".join(bad)


def test_the_conftest_check_catches_both_forms(tmp_path):
    p = tmp_path / "test_x.py"
    p.write_text("import os\nfrom conftest import ROOT\n\ndef test_a():\n    import conftest\n")
    assert _imports_conftest(p) == [2, 5]
