"""Imports point one way: app -> {lbm, raytrace} -> kernels (DESIGN.md)."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: what each package may import from the project
ALLOWED = {"kernels": {"kernels"}, "lbm": {"lbm", "kernels"},
           "raytrace": {"raytrace", "kernels"}}
PROJECT = {"app", "kernels", "lbm", "raytrace"}


def project_imports(path: Path) -> set[str]:
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out & PROJECT


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_import_against_the_direction(package):
    files = sorted((ROOT / package).glob("*.py"))
    assert files
    bad = {f.name: sorted(project_imports(f) - ALLOWED[package]) for f in files}
    assert not {k: v for k, v in bad.items() if v}, f"{package} imports against the direction"
