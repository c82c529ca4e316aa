"""``scripts/`` and ``benchmarks/`` stand beside the package: they import only its public names and subclass
none of its classes; the package never imports them."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "lerobot_indicator"


def _is_private(dotted: str) -> bool:
    return any(part.startswith("_") and not part.startswith("__") for part in dotted.split("."))


def violations(source: str) -> list[str]:
    """Subclassed package classes and private package names that ``source`` imports or reads."""
    tree = ast.parse(source)
    package_names: set[str] = set()  # local names bound to package modules or package objects
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == PACKAGE:
            for alias in node.names:
                if _is_private(f"{node.module}.{alias.name}"):
                    found.append(f"line {node.lineno}: imports {node.module}.{alias.name}")
                package_names.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == PACKAGE:
                    if _is_private(alias.name):
                        found.append(f"line {node.lineno}: imports {alias.name}")
                    package_names.add(alias.asname or alias.name.split(".")[0])
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _is_private(node.attr):
            root = node.value
            while isinstance(root, ast.Attribute):
                root = root.value
            if isinstance(root, ast.Name) and root.id in package_names:
                found.append(f"line {node.lineno}: reads {root.id}...{node.attr}")
        if isinstance(node, ast.ClassDef):
            for base in node.bases:
                root = base
                while isinstance(root, ast.Attribute):
                    root = root.value
                if isinstance(root, ast.Name) and root.id in package_names:
                    found.append(f"line {node.lineno}: class {node.name} subclasses {ast.unparse(base)}")
    return found


OUTSIDE = sorted(
    str(p.relative_to(ROOT)) for folder in ("scripts", "benchmarks") for p in (ROOT / folder).rglob("*.py")
)


@pytest.mark.parametrize("path", OUTSIDE)
def test_neither_subclasses_nor_imports_private_package_names(path):
    assert violations((ROOT / path).read_text()) == []


def test_benchmarks_live_outside_the_package():
    assert not (ROOT / PACKAGE / "bench").exists() and (ROOT / "benchmarks").is_dir()
    importers = []
    for path in (ROOT / PACKAGE).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else []
            names += [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if any(n.split(".")[0] == "benchmarks" for n in names):
                importers.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert importers == []


def test_the_scan_finds_each_kind_of_violation():
    source = """
from lerobot_indicator.training import online
from lerobot_indicator.training.online import _helper
import lerobot_indicator.envs._robosuite as rs
from lerobot_indicator.training.online import OnlineTrainer


class Timed(OnlineTrainer):
    pass


def f():
    class Inner(online.OnlineTrainer):
        pass
    return online._private_constant
"""
    found = violations(source)
    assert len(found) == 5, found
    assert any("_helper" in v for v in found) and any("_robosuite" in v for v in found)
    assert any("class Timed" in v for v in found) and any("class Inner" in v for v in found)
    assert any("_private_constant" in v for v in found)
    # Subclassing other libraries' classes (argparse, SB3 callbacks) is fine.
    assert violations("import argparse\nclass A(argparse.Action):\n    pass\n") == []
