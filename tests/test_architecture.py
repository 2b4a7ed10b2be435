"""Import rules of the package layout: arrows point down only (itr_identify ->
itr_surrogate -> itr_fft -> itr_fv); itr_fft uses the discrete problem of itr_fv, never its
solver; no import circle inside a package; nothing imports validation/ or tests/; the wheel
lists every subpackage."""

import ast
import re
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Import name -> the repository folder it is installed from (pyproject's package-dir).
PACKAGES = {"itr_fv": "itr_fv", "itr_fft": "itr_fft", "itr_surrogate": "surrogate",
            "itr_identify": "identify"}
LAYERS = list(PACKAGES)  # each may import those before it
#: Folder names that are not import names: importing them is always a mistake.
NOT_IMPORT_NAMES = {folder for name, folder in PACKAGES.items() if name != folder}


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
    files = sorted((ROOT / PACKAGES[package]).rglob("*.py"))
    assert files
    for f in files:
        for mod in imported_modules(f):
            top = mod.split(".")[0]
            assert top not in {"validation", "tests", "conftest"}, (f, mod)
            assert top not in NOT_IMPORT_NAMES, (
                f"{f.relative_to(ROOT)} imports {mod}: the folder {top}/ installs as "
                f"{next(n for n, d in PACKAGES.items() if d == top)}")
            if top in LAYERS:
                assert top in allowed, f"{f.relative_to(ROOT)} imports {mod}"


def test_itr_fft_never_uses_the_fv_solver():
    """itr_fft provides backends of the one door; it never solves through it, nor through
    the pyamg reference backend."""
    for f in sorted((ROOT / "itr_fft").rglob("*.py")):
        mods = imported_modules(f)
        assert not {m for m in mods if m in ("itr_fv.homogenize", "itr_fv.solvers.amg",
                                             "itr_fv.solvers.driver.homogenize")}, f


@pytest.mark.parametrize("package", LAYERS)
def test_compiled_kernels_cache_outside_the_installed_package(package):
    """Every CPU kernel compiles through :func:`itr_fv.numba_cache.njit`: numba's own
    ``cache=True`` writes into the package's ``__pycache__``, which ``pip uninstall`` leaves
    behind as a folder without ``__init__.py`` that shadows an editable install (CI broke on
    ``itr_identify.inference`` that way)."""
    for f in sorted((ROOT / PACKAGES[package]).rglob("*.py")):
        if f.name == "numba_cache.py":
            continue
        tree = ast.parse(f.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.keyword) and node.arg == "cache":
                assert not (isinstance(node.value, ast.Constant) and node.value.value), (
                    f"{f.relative_to(ROOT)}:{node.value.lineno} compiles with numba's own "
                    "cache=True; use itr_fv.numba_cache.njit")


# ------------------------------------------------------------------------ import circles
def package_modules(package: str) -> dict[str, Path]:
    """Dotted module name -> file, for every module of ``package`` (``__init__.py`` is the
    package's own module)."""
    folder = ROOT / PACKAGES[package]
    out = {}
    for f in sorted(folder.rglob("*.py")):
        parts = list(f.relative_to(folder).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join([package, *parts])] = f
    return out


def import_graph(package: str) -> dict[str, set[str]]:
    """Module-level import graph of ``package``: module -> the modules of the same package
    it imports anywhere in its file (top level or inside functions), absolute and relative
    imports resolved. ``from .x import name`` counts as importing the submodule ``x.name``
    where that is a module, else ``x``; importing a submodule does not count as importing
    its parent package's ``__init__``."""
    modules = package_modules(package)

    def resolve(name: str) -> str | None:
        """``name`` or its longest prefix that is a module of the package."""
        parts = name.split(".")
        while parts:
            candidate = ".".join(parts)
            if candidate in modules:
                return candidate
            parts.pop()
        return None

    graph: dict[str, set[str]] = {}
    for mod, path in modules.items():
        is_package = path.name == "__init__.py"
        here = mod.split(".") if is_package else mod.split(".")[:-1]
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base_parts = here[: len(here) - (node.level - 1)]
                    base = ".".join(base_parts + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [f"{base}.{alias.name}" for alias in node.names] or [base]
            for target in targets:
                if target.split(".")[0] != package:
                    continue
                found = resolve(target)
                if found is not None and found != mod:
                    edges.add(found)
        graph[mod] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a path that ends where it starts, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            cycle = visit(node)
            if cycle:
                return cycle
    return None


def test_find_cycle_reports_a_circle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set()}) is None
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]


def test_import_graph_resolves_relative_and_function_imports(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .sub import b\n")
    (pkg / "a.py").write_text("def f():\n    from .sub.b import g\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("from .. import a\nimport pkg.sub\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    monkeypatch.setitem(PACKAGES, "pkg", "pkg")
    graph = import_graph("pkg")
    assert graph == {"pkg": {"pkg.sub.b"}, "pkg.a": {"pkg.sub.b"}, "pkg.sub": set(),
                     "pkg.sub.b": {"pkg.a", "pkg.sub"}}
    assert find_cycle(graph) == ["pkg.sub.b", "pkg.a", "pkg.sub.b"]


@pytest.mark.parametrize("package", LAYERS)
def test_no_import_circle_inside_a_package(package):
    cycle = find_cycle(import_graph(package))
    assert cycle is None, f"import circle in {package}: {' -> '.join(cycle)}"


#: itr_identify's subpackages, each may import those before it (and itself).
IDENTIFY_LAYERS = ["forward", "inference", "discrepancy", "reporting", "workflows", "cli"]


def test_itr_identify_subpackages_point_down_only():
    graph = import_graph("itr_identify")
    subpackages = {m.split(".")[1] for m in graph if m.count(".") >= 1}
    assert subpackages == set(IDENTIFY_LAYERS), "a new subpackage: give it its layer"
    for mod, targets in graph.items():
        if mod.count(".") < 1:
            continue
        level = IDENTIFY_LAYERS.index(mod.split(".")[1])
        for t in targets:
            assert IDENTIFY_LAYERS.index(t.split(".")[1]) <= level, f"{mod} imports {t}"


#: itr_fv's subpackages by job, each may import those before it (and itself); its
#: top-level modules (checks, io, numba_cache, analytic) sit below all of them.
ITR_FV_LAYERS = ["materials", "rve", "discrete", "output", "solvers"]


def test_itr_fv_subpackages_point_down_only():
    graph = import_graph("itr_fv")
    subpackages = {m.split(".")[1] for m, f in graph.items()
                   if m.count(".") >= 1 and package_modules("itr_fv")[m].parent.name != "itr_fv"}
    assert subpackages == set(ITR_FV_LAYERS), "a new subpackage: give it its layer"
    for mod, targets in graph.items():
        if mod == "itr_fv":
            continue  # the package's __init__ gathers the public names
        layer = mod.split(".")[1]
        level = ITR_FV_LAYERS.index(layer) if layer in ITR_FV_LAYERS else -1
        for t in targets:
            t_layer = t.split(".")[1] if t.count(".") >= 1 else None
            t_level = ITR_FV_LAYERS.index(t_layer) if t_layer in ITR_FV_LAYERS else -1
            assert t_level <= level, f"{mod} imports {t}"


def test_itr_fv_holds_no_study_fixtures_and_old_paths_alias_the_new_modules():
    assert not (ROOT / "itr_fv" / "gallery.py").exists()
    import importlib
    import warnings

    from itr_fv._moved import MOVED
    for old, new in MOVED.items():
        assert not (ROOT / "itr_fv" / f"{old}.py").exists(), old
        assert (ROOT / "itr_fv" / (new.replace(".", "/") + ".py")).exists(), new
    with pytest.warns(DeprecationWarning, match="itr_fv.discrete.model"):
        sys.modules.pop("itr_fv.model", None)
        old_model = importlib.import_module("itr_fv.model")
    assert old_model is importlib.import_module("itr_fv.discrete.model")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from itr_fv.rve import FillerSpec, generate_rve  # noqa: F401  (public, not moved)


def test_face_geometry_asks_the_law_not_its_name():
    """A new interface law is one class: the face geometry builds what the law declares it
    needs, with no branch on the law's name."""
    text = (ROOT / "itr_fv" / "discrete" / "face_geometry.py").read_text(encoding="utf-8")
    assert not re.search(r"\.name\s*(==|!=|in\b)", text)


# ------------------------------------------------------------------------- the wheel
def test_pyproject_lists_every_package():
    """pyproject's explicit ``packages`` list is every folder with an ``__init__.py`` (a
    subpackage missing from it would be missing from the wheel), and ``package-dir`` maps
    the import names to the repository's folders."""
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    st = conf["tool"]["setuptools"]
    assert st["package-dir"] == {n: d for n, d in PACKAGES.items() if n != d}
    on_disk = set()
    for name, folder in PACKAGES.items():
        for init in (ROOT / folder).rglob("__init__.py"):
            rel = init.parent.relative_to(ROOT / folder).parts
            on_disk.add(".".join([name, *rel]))
    assert set(st["packages"]) == on_disk
    assert len(st["packages"]) == len(set(st["packages"]))
    assert conf["project"]["scripts"]["itr"] == "itr_identify.cli:main"
    # the paper's tables and materials are shipped in itr_fv/data (the bottom layer); the
    # package's own numerical studies, which the error budget reads, and the shipped
    # faithful corrections in identify/data
    data = conf["tool"]["setuptools"]["package-data"]
    assert data == {"itr_fv": ["data/*.csv", "data/README.md"],
                    "itr_identify": ["data/*.csv", "data/*.json"]}
    assert {p.name for p in (ROOT / "itr_fv" / "data").glob("*.csv")} >= {
        "psd_lognormal.csv", "conductivities.csv", "measured_tc.csv"}


# ------------------------------------------------------------------ one material system
#: The names of the paper's material system (and its views) in itr_fv.materials.paper_data.
PAPER_SYSTEM_NAMES = {"PAPER_SYSTEM", "PAPER_CONDUCTIVITY", "TABLE1"}


def _names(path: Path) -> set[str]:
    """Every name a module reads: bare names, attributes and imported names."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.Attribute):
            out.add(node.attr)
        elif isinstance(node, ast.ImportFrom):
            out.update(alias.name for alias in node.names)
    return out


def test_only_the_materials_package_reads_the_paper_system():
    """Every layer takes the material system from its settings: outside itr_fv.materials
    no module reads the paper's system or its views; the default is made there, once
    (itr_fv.materials.default_system), and the shipped measured defaults are tied to it
    by is_default_system."""
    materials = ROOT / "itr_fv" / "materials"
    readers = []
    for package in PACKAGES.values():
        for f in sorted((ROOT / package).rglob("*.py")):
            if materials in f.parents:
                continue
            hit = _names(f) & PAPER_SYSTEM_NAMES
            if hit:
                readers.append(f"{f.relative_to(ROOT)}: {sorted(hit)}")
    assert readers == []
    # and inside, the default's one maker reads it
    init = (materials / "__init__.py").read_text(encoding="utf-8")
    assert "def default_system" in init and "PAPER_SYSTEM" in init


# --------------------------------------------------------------------- one solver choice
def _string_constants(path: Path) -> set[str]:
    """The string constants a module's code holds, docstrings left out."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value,
                                                                     ast.Constant):
                docs.add(id(body[0].value))
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and id(node) not in docs}


def test_only_the_backend_layer_names_a_solver():
    """The solver is chosen in itr_fv.solvers.choice: outside the backend layer
    (itr_fv/solvers and the backends of itr_fft) no module reads DEFAULT_SOLVER or spells
    a registered solver's name; settings take the default from choice.default_solver and
    carry the resolved name they are given."""
    from itr_fv.solvers.choice import SOLVERS

    backend_layer = [ROOT / "itr_fv" / "solvers", ROOT / "itr_fft"]
    readers = []
    for package in PACKAGES.values():
        for f in sorted((ROOT / package).rglob("*.py")):
            if any(layer in f.parents for layer in backend_layer):
                continue
            if "DEFAULT_SOLVER" in _names(f):
                readers.append(f"{f.relative_to(ROOT)}: DEFAULT_SOLVER")
            named = _string_constants(f) & set(SOLVERS)
            if named:
                readers.append(f"{f.relative_to(ROOT)}: {sorted(named)}")
    assert readers == []


#: What the rest of the house may take from the solver choice: the object, the two ways
#: to make one (from what a user wrote; from a settings field), the default, and the
#: registry and devices that help texts list and the cost model reads.
CHOICE_FACE = {"Solver", "resolve_solver", "as_solver", "default_solver", "SOLVERS", "DEVICES",
               "DEFAULT_DEVICE", "solvers_for", "load_case_seconds", "SolverChoice"}


def test_a_solver_travels_as_one_object():
    """Below the command line and the settings a solver is a Solver, never a name: no
    module outside itr_fv/solvers takes anything else from the choice (no look-up of a
    name), no field or argument of the four packages is annotated ``solver: str``, and a
    name is made into a Solver only by the command line (resolve_solver) or a settings
    class, request or estimator that takes a user's value (as_solver)."""
    offenders = []
    for package in PACKAGES.values():
        for f in sorted((ROOT / package).rglob("*.py")):
            if ROOT / "itr_fv" / "solvers" in f.parents:
                continue
            text = f.read_text(encoding="utf-8")
            taken = {m.rsplit(".", 1)[1] for m in imported_modules(f)
                     if m.startswith("itr_fv.solvers.choice.")}
            if taken - CHOICE_FACE:
                offenders.append(f"{f.relative_to(ROOT)}: {sorted(taken - CHOICE_FACE)}")
            # (a result records the backend that ran by its name: the result protocol of
            # the VTK writer reads that record, not a choice)
            if re.search(r"\bsolver: str\b", text) and f.name != "vtk.py":
                offenders.append(f"{f.relative_to(ROOT)}: solver: str")
    assert offenders == []


def test_one_door_to_a_solve():
    """One ``homogenize`` in the four packages: itr_fv.homogenize (the driver's)."""
    import itr_fv
    from itr_fv.solvers import driver

    found = []
    for package in PACKAGES.values():
        for f in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(f.read_text(encoding="utf-8"))
            found += [f"{f.relative_to(ROOT)}:{node.lineno}" for node in ast.walk(tree)
                      if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
                      and node.name == "homogenize"]
    assert found == ["itr_fv/solvers/driver.py:" + found[0].rsplit(":", 1)[1]], found
    assert itr_fv.homogenize is driver.homogenize


def _function_lengths(package: str):
    for f in sorted((ROOT / package).rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield f"{f.relative_to(ROOT)}:{node.name}", node.end_lineno - node.lineno + 1


@pytest.mark.parametrize("package", LAYERS)
def test_no_function_over_a_hundred_lines(package):
    """Functions of one job: none over 100 lines (the aim is ~80)."""
    long = sorted((n, name) for name, n in _function_lengths(PACKAGES[package]) if n > 100)
    assert long == []


def test_the_engine_room_holds_the_engine_alone():
    """surrogate/engine.py is SolveEngine: requests and payloads, the worker's side, the
    cluster set-up and the Parquet stores live in rooms of their own."""
    text = (ROOT / "surrogate" / "engine.py").read_text(encoding="utf-8")
    tree = ast.parse(text)
    top = [n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))]
    assert top == ["SolveEngine"] and len(text.splitlines()) <= 300


def test_no_worker_path_reaches_the_default_system(monkeypatch):
    """What runs on a Dask worker (a campaign's task, an engine's request) works from what
    the client sent: with the package's default material system made to fail, a campaign of
    another system (ZnO in epoxy) and a request solve in full."""
    import itr_fv.materials as materials
    from itr_fv import Materials
    from itr_fv.materials.system_file import read_system
    from itr_surrogate import campaign as campaign_module
    from itr_surrogate.campaign import Campaign
    from itr_surrogate.requests import RVEData, SolveRequest, request_payload
    from itr_surrogate.runner import campaign_rve, run_task
    from itr_surrogate.worker import run_payload

    system = read_system(next((ROOT / "examples" / "zno_epoxy").glob("*system*.toml")))
    filler = system.filler_names[0]
    camp = Campaign.from_dict({
        "name": "elsewhere", "box_um": 4.0, "voxel_um": 0.25, "replicas": 1, "seed": 3,
        "formulation": [{"name": f"{filler}-30", "fractions": {filler: 0.3}}],
        "design": {"kind": "grid", "values": {f"R_{filler}_{system.matrix}": [1e-8]}}},
        system)
    task = camp.tasks()[0]
    ms, _ = campaign_rve(camp, task.formulation, task.replica)
    mat = Materials(system.conductivities([filler]), {(filler, system.matrix): 1e-8},
                    matrix=system.matrix)
    payload = request_payload(SolveRequest.for_materials(RVEData.of(ms), mat, 1e-6))

    def refuse():
        raise AssertionError("a worker path reached default_system()")

    for module in (materials, campaign_module):
        monkeypatch.setattr(module, "default_system", refuse)
    monkeypatch.setattr(materials, "is_default_system", lambda s: refuse())
    monkeypatch.setattr(campaign_module, "is_default_system", lambda s: refuse())
    rows = run_task(camp, task)["rows"]
    assert len(rows) == 1 and rows[0]["k_iso"] > system.conductivities()[system.matrix]
    assert run_payload(payload)["k_eff"][0][0] > 0
