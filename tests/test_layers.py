"""The package's layers, read from its source: algorithms import no ROS, nothing but the benchmarks imports them, the
core modules import no subpackage, and every domain error derives from the package's root error."""

import ast
import inspect
from pathlib import Path

import sit2stand
from sit2stand import errors

PACKAGE = Path(sit2stand.__file__).parent
CORE = ("vectors", "errors", "forceplate", "dynamics", "kinematics", "optim", "scheduling", "native", "cache")
"""Modules at the bottom: plain mathematics, its compiled kernels (``native``, a package), the cache folder and the
error types, importing only each other."""
ROS_LAYERS = ("nodes", "bench")
"""Where rclpy may be imported: the nodes, and benchmarks that drive them."""


def _modules() -> dict[str, ast.Module]:
    """Every module of the package by dotted name relative to it (``io.bag``; a package's ``__init__`` as
    ``io.__init__``), parsed."""
    return {".".join(path.relative_to(PACKAGE).with_suffix("").parts): ast.parse(path.read_text(), str(path))
            for path in sorted(PACKAGE.rglob("*.py"))}


def _imports(name: str, tree: ast.Module) -> set[str]:
    """What ``name`` imports anywhere (functions included): absolute names, the package's own as ``sit2stand.x``."""
    package = ["sit2stand", *name.split(".")[:-1]]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            out.add(module)
            out.update(f"{module}.{a.name}" for a in node.names)
    return out


MODULES = _modules()


def test_only_nodes_and_benchmarks_import_ros():
    offenders = {n for n, t in MODULES.items() if n.split(".")[0] not in ROS_LAYERS
                 and any(i == "rclpy" or i.startswith("rclpy.") for i in _imports(n, t))}
    assert not offenders, f"rclpy imported outside the nodes: {sorted(offenders)}"


def test_nothing_but_the_benchmarks_imports_them():
    offenders = {n for n, t in MODULES.items() if n.split(".")[0] != "bench"
                 and any(i.startswith("sit2stand.bench") for i in _imports(n, t))}
    assert not offenders, f"modules that import a benchmark: {sorted(offenders)}"


def test_core_modules_import_no_subpackage():
    for name in CORE:
        key = name if name in MODULES else f"{name}.__init__"
        own = {i for i in _imports(key, MODULES[key]) if i.startswith("sit2stand.")}
        above = {i for i in own if i.split(".")[1] not in CORE}
        assert not above, f"sit2stand.{name} imports {sorted(above)}"


def test_every_domain_error_derives_from_the_root():
    loose, domain = [], _domain_errors()
    for name, tree in MODULES.items():
        for node in ast.walk(tree):
            if not isinstance(node, ast.ClassDef) or node.name == "Sit2StandError":
                continue
            bases = {ast.unparse(b).split(".")[-1] for b in node.bases}
            if any(b.endswith(("Error", "Exception")) for b in bases):       # an exception type
                if not bases & domain:
                    loose.append(f"{name}.{node.name}({', '.join(sorted(bases))})")
    assert not loose, f"errors outside Sit2StandError: {loose}"


def _domain_errors() -> set[str]:
    """Names of the root error and of every class deriving from it anywhere in the package (by name)."""
    names = {"Sit2StandError", *(n for n, c in inspect.getmembers(errors, inspect.isclass)
                                  if issubclass(c, errors.Sit2StandError))}
    grew = True
    while grew:
        grew = False
        for tree in MODULES.values():
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef) and node.name not in names and \
                        {ast.unparse(b).split(".")[-1] for b in node.bases} & names:
                    names.add(node.name)
                    grew = True
    return names
