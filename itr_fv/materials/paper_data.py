"""The reference paper's tables and material system, shipped with the package
(``itr_fv/data/*.csv``): the one place they are read.

The tables are transcribed from the paper (Tables 1-6, and the conductivities of its
Sections 2.4 and 3.2 in ``conductivities.csv``); ``data/README.md`` lists the paper's own
inconsistencies. Readers return plain Python structures; units are in the column names
(W/(m K), m^2 K/W, volume per cent, micrometres). :data:`PAPER_SYSTEM` is the paper's
material system (matrix, fillers, Table 1 size distributions, conductivities) as one
:class:`~itr_fv.materials.material_system.MaterialSystem`; :data:`TABLE1` and
:data:`PAPER_CONDUCTIVITY` are views of it.
"""

from __future__ import annotations

import csv
from importlib import resources

from .material_system import Filler, MaterialSystem
from .parameters import parameter_name
from .psd import LogNormalPSD

__all__ = ["read_table", "table_text", "formulations", "psd_lognormal", "paper_resistances",
           "PAPER_SYSTEM", "PAPER_CONDUCTIVITY", "TABLE1", "paper_parameters",
           "paper_validation"]

TABLES = ("formulations", "measured_tc", "paper_itr", "paper_validation", "parameter_grid",
          "psd_lognormal", "conductivities", "densities")


def table_text(name: str) -> str:
    """The CSV text of the shipped table ``name`` (one of :data:`TABLES`)."""
    if name not in TABLES:
        raise ValueError(f"name: expected one of {TABLES}, got {name!r}")
    return resources.files("itr_fv").joinpath("data", f"{name}.csv").read_text()


def read_table(name: str) -> list[dict[str, str]]:
    """Rows of the shipped table ``name`` (one of :data:`TABLES`) as dictionaries of strings."""
    return list(csv.DictReader(table_text(name).splitlines()))


def formulations() -> dict[str, dict[str, float]]:
    """Table 2: formulation -> {filler: volume fraction (0-1)}, fillers with a zero share
    left out."""
    out = {}
    for row in read_table("formulations"):
        fr = {"Al2O3": float(row["Al2O3_vol_pct"]) / 100, "AlN": float(row["AlN_vol_pct"]) / 100}
        out[row["formulation"]] = {k: v for k, v in fr.items() if v > 0}
    return out


def psd_lognormal() -> dict[str, tuple[float, float]]:
    """Table 1: filler -> (mu, sigma) of ln(D / 1 um)."""
    return {r["material"]: (float(r["mu_ln_um"]), float(r["sigma_ln"]))
            for r in read_table("psd_lognormal")}


def _paper_system() -> MaterialSystem:
    psd = psd_lognormal()
    rows = read_table("conductivities")
    rho = {r["material"]: float(r["density_g_per_cm3"]) for r in read_table("densities")}
    (matrix,) = [r for r in rows if r["role"] == "matrix"]
    fillers = tuple(Filler(r["material"], float(r["k_W_per_mK"]),
                           LogNormalPSD(*psd[r["material"]], "number"), rho.get(r["material"]),
                           conductivity_sd=float(r["rel_sd"]),
                           size_note="lognormal mu/sigma, number basis (Table 1)")
                    for r in rows if r["role"] == "filler")
    named = tuple((name, tuple(sorted(parts.items())))
                  for name, parts in formulations().items())
    return MaterialSystem(matrix["material"], float(matrix["k_W_per_mK"]), fillers,
                          rho.get(matrix["material"]),
                          matrix_conductivity_sd=float(matrix["rel_sd"]), named=named,
                          name="paper", source="the package's tables of the paper")


#: The paper's material system: silicone 0.18 W/(m K) with Al2O3 (30) and AlN (200) of the
#: Table 1 size distributions (the hybrids are simulated at these fixed values), Table 2's
#: formulations by name. The package's default system (:func:`itr_fv.materials.default_system`).
PAPER_SYSTEM = _paper_system()
#: The conductivities the paper simulates with, W/(m K) (a view of :data:`PAPER_SYSTEM`).
PAPER_CONDUCTIVITY = PAPER_SYSTEM.conductivities()
#: Table 1 of the paper: filler -> number-weighted lognormal of ln(D / 1 um) (a view of
#: :data:`PAPER_SYSTEM`).
TABLE1: dict[str, LogNormalPSD] = PAPER_SYSTEM.size_distributions()


def paper_parameters(matrix: str = "silicone") -> dict[str, float]:
    """The paper's values under the flat names: ``k_<phase>`` of :data:`PAPER_CONDUCTIVITY`
    and the filler-matrix resistances ``R_<filler>_<matrix>`` of Table 5."""
    out = {parameter_name("k", p): v for p, v in PAPER_CONDUCTIVITY.items()}
    out.update({parameter_name("R", a, b): v for (a, b), v in paper_resistances().items()
                if matrix in (a, b)})
    return out


def paper_resistances() -> dict[tuple[str, str], float]:
    """Table 5: (phase, phase) -> the paper's identified resistance, m^2 K/W."""
    out = {}
    for r in read_table("paper_itr"):
        a, b = r["interface"].split("-")
        out[(a, b)] = float(r["R_m2K_per_W"])
    return out


def paper_validation() -> dict[str, tuple[float, float]]:
    """Table 6: formulation -> (measured, predicted) conductivity, W/(m K)."""
    return {r["formulation"]: (float(r["measured_W_per_mK"]), float(r["predicted_W_per_mK"]))
            for r in read_table("paper_validation")}
