"""Import rules of the package layout: arrows point down only (identify -> surrogate ->
itr_fft -> itr_fv); itr_fft uses the discrete problem of itr_fv, never its solver; nothing
imports validation/ or tests/."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ["itr_fv", "itr_fft", "surrogate", "identify"]  # each may import those before it


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.add(node.module)
            out.update(f"{node.module}.{alias.name}" for alias in node.names)
    return out


@pytest.mark.parametrize("package", LAYERS)
def test_imports_point_down_only(package):
    allowed = set(LAYERS[: LAYERS.index(package) + 1])
    files = sorted((ROOT / package).rglob("*.py"))
    assert files
    for f in files:
        for mod in imported_modules(f):
            top = mod.split(".")[0]
            assert top not in {"validation", "tests", "conftest"}, (f, mod)
            if top in LAYERS:
                assert top in allowed, f"{f.relative_to(ROOT)} imports {mod}"


def test_itr_fft_never_uses_the_fv_solver():
    for f in sorted((ROOT / "itr_fft").rglob("*.py")):
        mods = imported_modules(f)
        assert not {m for m in mods if m in ("itr_fv.solver", "itr_fv.homogenize",
                                             "itr_fv.solver.homogenize")}, f
        assert "itr_fv.homogenize" not in f.read_text(encoding="utf-8"), f
