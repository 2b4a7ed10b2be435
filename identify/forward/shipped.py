"""Faithful corrections shipped with the package: ``c = k_faithful / k_cheap`` as data.

The factor that takes the cheap RVE's conductivity (:data:`~itr_identify.forward.fidelity.
CHEAP_RVE`, the level the reduced basis stands for) to the converged box's with the voxel
bias removed depends on the formulation and weakly on the resistances, not on the
measurements. It is computed once (:func:`assemble`, from the campaigns of
:mod:`itr_identify.forward.correction_plan`) and shipped as ``identify/data/corrections.json``
with its provenance. Per design point and formulation,

    k_0,j = richardson(k_h,j, k_H,j)          (packing j, voxel bias removed, W/(m K))
    c     = mean_j k_0,j / mean_r k_cheap,r    (dimensionless)

and its standard uncertainty is the packings' (direction-based scatter over sqrt(J)) and
the bias order's (``p +- 2 se``) in quadrature. Per filler system the factors are fitted by

    c(phi, R) = a + b (phi - phi_0) + sum_i d_i log10(R_i / R_0)

(``phi`` the total filler fraction, ``R_0`` the design's geometric centre): a smooth function
of the fraction within the studied range, whose residual RMS is the interpolation's
uncertainty. :class:`ShippedCorrections` gives the factor and its relative standard
uncertainty for any formulation of a studied system within its fraction range (a hybrid:
1:1); outside that, None, and the identification falls back to runtime corrections.
Resistances beyond the design's range take the nearest design value's factor, and the
fitted slope over the distance is added to the uncertainty.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import subprocess
from collections.abc import Mapping
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from itr_fv.materials import is_default_system
from itr_fv.materials.material_system import MaterialSystem
from itr_fv.rve.contact_film import CONTACT_GEOMETRY
from itr_fv.rve.spec import RVESpec

from .correction_plan import CorrectionPlan
from .fidelity import (
    BIAS_ORDER,
    BIAS_ORDER_SE,
    CHEAP_REPLICAS,
    CHEAP_TOL,
    direction_scatter,
    richardson,
)

__all__ = ["ShippedCorrections", "ShippedFactor", "assemble", "campaign_rows", "point_rows",
           "SHIPPED_FILE"]

SHIPPED_FILE = "corrections.json"
#: How far a hybrid may be from 1:1 (difference of the two fractions) and still use the 1:1
#: fit, volume fraction.
HYBRID_TOLERANCE = 0.005


def campaign_rows(folder: Path) -> list[dict]:
    """A campaign store's rows, or where there is none the rows of ``<folder>.rows.json``
    (rows kept without their store, e.g. read back from a device run's log)."""
    from itr_surrogate.store import CampaignStore

    if (folder / "campaign.json").is_file():
        store = CampaignStore(folder)
        return store.results().to_pylist() if store.done_tasks() else []
    loose = folder.with_name(folder.name + ".rows.json")
    return json.loads(loose.read_text()) if loose.is_file() else []


def _diagonal(row: Mapping) -> np.ndarray:
    """(k_xx, k_yy, k_zz) of a row; NaN where only k_iso was kept."""
    if row.get("k_xx") is None:
        return np.full(3, np.nan)
    return np.array([row["k_xx"], row["k_yy"], row["k_zz"]], dtype=np.float64)


def _packing_sd(k0: np.ndarray, k0_iso: np.ndarray) -> float:
    """Relative standard error of the packings' mean k_iso: from the diagonal entries where
    kept (:func:`direction_scatter`), else from the packings' k_iso alone."""
    if np.all(np.isfinite(k0)):
        return direction_scatter(k0) / math.sqrt(len(k0))
    return float(k0_iso.std(ddof=1) / k0_iso.mean() / math.sqrt(len(k0_iso)))


def _key(row: Mapping, names: list[str]) -> tuple:
    return (row["formulation"],) + tuple(round(float(row[n]) * 1e12) for n in names)


def point_rows(plan: CorrectionPlan, folder: str | Path, system: str) -> list[dict]:
    """The assembled design points of one system from its campaign stores under ``folder``
    (only points whose every packing is solved at both voxels and whose cheap replicas are
    all solved): formulation, fractions, resistances, k_cheap, per-packing k at both
    voxels, the extrapolated k_0, c and its uncertainties."""
    s = plan.system(system)
    names = sorted(s.values)
    sub = plan.folders(system)
    group: dict[str, dict[tuple, dict[int, tuple[np.ndarray, float]]]] = {}
    for which in sub:
        group[which] = {}
        for r in campaign_rows(Path(folder) / sub[which]):
            group[which].setdefault(_key(r, names), {})[int(r["replica"])] = (
                _diagonal(r), float(r["k_iso"]))
    if "only" in sub:
        return _one_voxel_points(plan, folder, s, names, group)
    coarse_v, fine_v = plan.voxels_of(system)
    out = []
    for key, coarse in sorted(group["coarse"].items()):
        fine, cheap = group["fine"].get(key, {}), group["cheap"].get(key, {})
        packs = sorted(set(coarse) & set(fine))
        if len(packs) < plan.packings or len(cheap) < CHEAP_REPLICAS:
            continue
        kf = np.array([fine[j][1] for j in packs])      # k_iso per packing
        kc = np.array([coarse[j][1] for j in packs])
        ratio = coarse_v / fine_v
        k0 = richardson(kf, kc, ratio, BIAS_ORDER)
        k0_diag = richardson(np.array([fine[j][0] for j in packs]),
                             np.array([coarse[j][0] for j in packs]), ratio, BIAS_ORDER)
        k_cheap = float(np.mean([cheap[r][1] for r in sorted(cheap)]))
        k_faithful = float(k0.mean())
        lo, hi = (richardson(kf, kc, ratio, BIAS_ORDER + d).mean()
                  for d in (-2 * BIAS_ORDER_SE, 2 * BIAS_ORDER_SE))
        u_order = abs(hi - lo) / 2 / k_faithful
        out.append({"formulation": key[0], "fractions": _fractions(key[0], plan),
                    "values": {n: v / 1e12 for n, v in zip(names, key[1:])},
                    "k_cheap": k_cheap, "k_fine_iso": kf.tolist(), "k_coarse_iso": kc.tolist(),
                    "k_faithful_iso": k0.tolist(), "k_faithful": k_faithful,
                    "c": k_faithful / k_cheap, "packing_sd": _packing_sd(k0_diag, k0),
                    "order_sd": u_order, "cheap_sd": _cheap_sd(cheap),
                    "voxel_bias": float(kf.mean() / k_faithful - 1),
                    "voxel_bias_coarse": float(kc.mean() / k_faithful - 1)})
    return out


def _one_voxel_points(plan: CorrectionPlan, folder: str | Path, s, names: list[str],
                      group: dict) -> list[dict]:
    """Points of a system solved at one voxel: each packing's k over ``1 + b``, ``b`` the
    mean voxel bias of the ``bias_from`` systems at that voxel (each at its own filler's
    resistance of the point; the mean over that system's fractions), its uncertainty half
    their spread and their bias orders' in quadrature."""
    voxel = plan.voxels_of(s.name)[0]
    biases: dict[str, dict[float, list[tuple[float, float]]]] = {}
    for b in s.bias_from:
        (param,) = plan.system(b).values
        key = "voxel_bias_coarse" if voxel == plan.voxels_of(b)[0] else "voxel_bias"
        for p in point_rows(plan, folder, b):
            biases.setdefault(param, {}).setdefault(round(p["values"][param] * 1e12), []).append(
                (p[key], p["order_sd"]))
    out = []
    for key, only in sorted(group["only"].items()):
        cheap = group["cheap"].get(key, {})
        packs = sorted(only)
        values = {n: v / 1e12 for n, v in zip(names, key[1:])}
        per = [biases.get(n, {}).get(round(values[n] * 1e12)) for n in names]
        if len(packs) < plan.packings or len(cheap) < CHEAP_REPLICAS or any(
                not x for x in per):
            continue
        b_each = [float(np.mean([b for b, _ in x])) for x in per]
        bias = float(np.mean(b_each))
        u_bias = math.hypot((max(b_each) - min(b_each)) / 2,
                            float(np.mean([u for x in per for _, u in x])))
        kv = np.array([only[j][1] for j in packs])
        k0 = kv / (1 + bias)
        k0_diag = np.array([only[j][0] for j in packs]) / (1 + bias)
        k_cheap = float(np.mean([cheap[r][1] for r in sorted(cheap)]))
        k_faithful = float(k0.mean())
        out.append({"formulation": key[0], "fractions": _fractions(key[0], plan), "values": values,
                    "k_cheap": k_cheap, "k_voxel_iso": kv.tolist(), "voxel_um": voxel,
                    "k_faithful_iso": k0.tolist(), "k_faithful": k_faithful,
                    "c": k_faithful / k_cheap, "packing_sd": _packing_sd(k0_diag, k0),
                    "order_sd": u_bias, "cheap_sd": _cheap_sd(cheap), "voxel_bias": bias,
                    "voxel_bias_from": dict(zip(s.bias_from, b_each))})
    return out


def _cheap_sd(cheap: Mapping[int, tuple[np.ndarray, float]]) -> float:
    """Relative standard error of the cheap replicas' mean k_iso."""
    k = np.array([cheap[r][1] for r in sorted(cheap)])
    return float(k.std(ddof=1) / k.mean() / math.sqrt(len(k)))


def _fractions(name: str, plan: CorrectionPlan) -> dict[str, float]:
    from itr_fv.materials.formulation_names import fractions_of

    return fractions_of(name, plan.material)


def _design(points: list[dict], names: list[str]) -> tuple[np.ndarray, float, dict]:
    phi = np.array([sum(p["fractions"].values()) for p in points])
    phi0 = float(np.round(phi.mean(), 4))
    centre = {n: math.sqrt(min(p["values"][n] for p in points)
                           * max(p["values"][n] for p in points)) for n in names}
    cols = [np.ones_like(phi), phi - phi0] + [
        np.log10(np.array([p["values"][n] for p in points]) / centre[n]) for n in names]
    return np.column_stack(cols), phi0, centre


def fit_system(points: list[dict], names: list[str]) -> dict[str, Any]:
    """Least-squares fit of ``c(phi, R)`` to a system's points (see the module docstring);
    a linear trend in the fraction needs two fractions at least."""
    fractions = sorted({round(sum(p["fractions"].values()), 6) for p in points})
    if len(fractions) < 2:
        raise ValueError(f"points: a fit over the fraction needs two fractions, got "
                         f"{fractions}")
    X, phi0, centre = _design(points, names)
    y = np.array([p["c"] for p in points])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    dof = max(len(y) - X.shape[1], 1)
    return {"parameters": names, "phi0": phi0, "R0": centre,
            "coefficients": coef.tolist(), "fit_rms": float(math.sqrt(resid @ resid / dof)),
            "fraction_range": [fractions[0], fractions[-1]],
            "R_range": {n: [min(p["values"][n] for p in points),
                            max(p["values"][n] for p in points)] for n in names},
            "packing_sd": float(np.sqrt(np.mean([p["packing_sd"] ** 2 for p in points]))),
            "order_sd": float(np.sqrt(np.mean([p["order_sd"] ** 2 for p in points]))),
            "voxel_bias": float(np.mean([p["voxel_bias"] for p in points])),
            "cheap_sd": float(np.sqrt(np.mean([p["cheap_sd"] ** 2 for p in points]))),
            "max_residual": float(np.abs(resid).max())}


#: The relative uncertainty a factor of a table built with the earlier contact geometry
#: carries for it (:attr:`ShippedCorrections.stale_contacts`): the packer's clearance, read
#: there as a film, lowers k_iso more in a converged box than in the cheap RVE (larger
#: particles, larger clearance), so such a factor reads low, by 1-3 % for AlN-60 at
#: R = 3e-8 (validation/results/box_study.md, "the contact geometry's share").
STALE_CONTACTS_SD = 0.03


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=Path(__file__).resolve().parent, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def assemble(plan: CorrectionPlan, folder: str | Path, *,
             provenance: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The shipped file's content from the finished campaigns of ``plan`` under ``folder``:
    every point, a fit per system (systems with points of two fractions at least) and the
    provenance (commit, date, boxes, voxels, seeds, solver, cheap RVE; ``provenance`` adds or
    replaces entries, e.g. where each campaign was solved)."""
    systems, points = {}, []
    for s in plan.systems:
        pts = point_rows(plan, folder, s.name)
        for p in pts:
            p["system"] = s.name
        points += pts
        try:
            systems[s.name] = {"fillers": sorted(pts[0]["fractions"]) if pts else [],
                               "box_um": s.box_um, **fit_system(pts, sorted(s.values))}
        except (ValueError, IndexError):
            continue
    prov = {"plan": plan.name, "commit": _commit(),
            "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d"),
            "boxes_um": {s.name: s.box_um for s in plan.systems},
            "voxels_um": list(plan.voxels_um), "packings": plan.packings,
            "seeds": [plan.seed + j for j in range(plan.packings)], "solver": plan.solver,
            "tol": plan.tol, "bias_order": BIAS_ORDER, "bias_order_se": BIAS_ORDER_SE,
            "contacts": CONTACT_GEOMETRY,
            "cheap_rve": {**plan.cheap_rve.to_dict(), "replicas": CHEAP_REPLICAS,
                          "seeds": [plan.cheap_rve.seed + r for r in range(CHEAP_REPLICAS)],
                          "tol": CHEAP_TOL},
            "material_system": plan.material.to_dict(),
            **dict(provenance or {})}
    return {"provenance": prov, "systems": systems, "points": points}


def _solve_key(system: Mapping[str, Any]) -> tuple:
    """What solves depend on in a material system's dict (MaterialSystem.to_dict): the
    phases, conductivities, size distributions (number basis) and known resistances."""
    m = system["matrix"]
    fillers = []
    for f in system["fillers"]:
        size = f["size"]
        mu = size["mu_ln_um"] - (3 * size["sigma_ln"] ** 2 if size["basis"] == "volume" else 0)
        fillers.append((f["name"], round(f["conductivity_W_per_mK"], 12), round(mu, 12),
                        round(size["sigma_ln"], 12)))
    return (m["name"], round(m["conductivity_W_per_mK"], 12), tuple(fillers),
            tuple(sorted(system.get("resistances_m2K_per_W", {}).items())))


@dataclass(frozen=True)
class ShippedFactor:
    """The shipped correction of one formulation: :meth:`factor` per row of resistances."""

    system: str
    fraction: float
    fit: dict[str, Any]
    own: tuple[dict, ...] = ()
    stale_sd: float = 0.0

    def _columns(self, columns: Mapping[str, np.ndarray], n: int) -> tuple[list, np.ndarray]:
        """Per parameter log10(R / R0) clipped into the design's range, and the distance
        beyond it (log10)."""
        f = self.fit
        xs, beyond = [], []
        for name in f["parameters"]:
            lo, hi = f["R_range"][name]
            v = np.broadcast_to(np.asarray(columns.get(name, f["R0"][name]), float), (n,))
            xs.append(np.log10(np.clip(v, lo, hi) / f["R0"][name]))
            beyond.append(np.abs(np.log10(np.clip(v, lo, hi) / v)))
        return xs, np.array(beyond).reshape(len(xs), n)

    def factor(self, columns: Mapping[str, np.ndarray], n: int) -> tuple[np.ndarray,
                                                                         np.ndarray]:
        """(c, relative standard uncertainty), each (n,), for ``{name: values}`` columns
        (m^2 K/W; a parameter not given sits at the design's centre).

        A formulation the table holds (:attr:`own`, its design points) takes its own
        factors, interpolated in log10 R (linear; bilinear for two resistances), with the
        packings' and the bias order's uncertainty: its cheap replicas are the ones the
        factors were computed for. Any other takes the system's fit at its fraction, with
        the fit's residual (at least the cheap replicas' scatter of their mean) added."""
        f = self.fit
        xs, beyond = self._columns(columns, n)
        if self.own:
            _, coef = _local_fit(self.own, f)
            c = coef[0] + sum(coef[1 + i] * x for i, x in enumerate(xs))
            if len(xs) == 2:
                c = c + coef[3] * xs[0] * xs[1]
            slopes = np.abs(coef[1:1 + len(xs)])
            u = math.sqrt(np.mean([p["packing_sd"] ** 2 + p["order_sd"] ** 2
                                   for p in self.own]))
        else:
            coef = np.asarray(f["coefficients"])
            c = coef[0] + coef[1] * (self.fraction - f["phi0"]) + sum(
                coef[2 + i] * x for i, x in enumerate(xs))
            slopes = np.abs(coef[2:])
            # another formulation's cheap replicas are other packings: their mean's scatter
            # is part of the interpolation's error (the fit's residual holds it only where
            # the system has more fractions than the fit has terms)
            interp = max(f["fit_rms"], f.get("cheap_sd", 0.0))
            u = math.sqrt(interp ** 2 + f["packing_sd"] ** 2 + f["order_sd"] ** 2)
        c = np.broadcast_to(np.asarray(c, dtype=np.float64), (n,)).copy()
        extra = np.sqrt(np.sum((slopes[:, None] * beyond) ** 2, axis=0))
        return c, np.hypot(np.hypot(u, self.stale_sd), extra / np.maximum(c, 1e-12))


def _local_fit(points: tuple[dict, ...], fit: Mapping[str, Any]) -> tuple[np.ndarray,
                                                                          np.ndarray]:
    """Coefficients of ``c = a + sum_i d_i x_i (+ e x_1 x_2)`` through one formulation's
    design points (``x_i = log10(R_i / R0_i)``): exact on a 2-point line or a 2 x 2 grid."""
    names = fit["parameters"]
    xs = [np.log10(np.array([p["values"][n] for p in points]) / fit["R0"][n]) for n in names]
    cols = [np.ones(len(points)), *xs] + ([xs[0] * xs[1]] if len(xs) == 2 else [])
    X = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(X, np.array([p["c"] for p in points]), rcond=None)
    return X, coef


#: The top-level entries of a corrections table and the JSON type each must have.
_TABLE_KEYS = {"provenance": dict, "systems": dict, "points": list}
#: JSON's names of the Python types :func:`json.loads` gives.
_JSON_NAMES = {dict: "object", list: "list", str: "string", int: "number", float: "number",
               bool: "true/false", type(None): "null"}


def _not_a_table(data: object) -> str | None:
    """Why ``data`` (a file's parsed JSON) is no corrections table, or None where it is one
    (its top-level entries: :data:`_TABLE_KEYS`)."""
    if not isinstance(data, dict):
        return (f"a JSON {_JSON_NAMES.get(type(data), 'value')}, not an object with "
                f"{', '.join(_TABLE_KEYS)}")
    missing = [k for k in _TABLE_KEYS if k not in data]
    if missing:
        return f"no {', '.join(repr(k) for k in missing)}"
    for key, kind in _TABLE_KEYS.items():
        if not isinstance(data[key], kind):
            return f"{key!r} is a JSON {_JSON_NAMES.get(type(data[key]), 'value')}, not " \
                   f"{'an object' if kind is dict else 'a list'}"
    return None


def _read_table(path: str | Path, argument: str) -> dict[str, Any]:
    """The parsed corrections table at ``path``; a ValueError naming ``argument`` and the path
    where it is no readable file or no corrections table."""
    p = Path(path)
    if not p.exists():
        raise ValueError(f"{argument}: {str(p)!r} does not exist")
    if not p.is_file():
        raise ValueError(f"{argument}: {str(p)!r} is not a file")
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ValueError(f"{argument}: {str(p)!r} is not a corrections table (not UTF-8 "
                         "text)") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{argument}: {str(p)!r} is not a corrections table (not JSON: "
                         f"{exc})") from None
    except OSError as exc:
        raise ValueError(f"{argument}: cannot read {str(p)!r} ({exc.strerror})") from None
    why = _not_a_table(data)
    if why:
        raise ValueError(f"{argument}: {str(p)!r} is not a corrections table ({why})")
    return data


class ShippedCorrections:
    """The corrections file: per filler system a fit of ``c(phi, R)`` and its range."""

    def __init__(self, data: Mapping[str, Any]) -> None:
        why = _not_a_table(dict(data) if isinstance(data, Mapping) else data)
        if why:
            raise ValueError(f"data: not a corrections table ({why})")
        self.data = dict(data)

    @classmethod
    def load(cls, path: str | Path | None = None, *,
             argument: str = "path") -> ShippedCorrections:
        """The corrections table at ``path`` (default: the one shipped in the package).

        Raises
        ------
        ValueError
            Naming ``argument`` and the path: no such file, not JSON, or JSON that is no
            corrections table (no ``provenance``, ``systems`` and ``points``).
        """
        if path is None:
            text = resources.files("itr_identify").joinpath("data", SHIPPED_FILE).read_text()
            return cls(json.loads(text))
        return cls(_read_table(path, argument))

    @property
    def provenance(self) -> dict[str, Any]:
        return dict(self.data["provenance"])

    @property
    def stale_contacts(self) -> bool:
        """Whether the table was built with another contact geometry than the model's
        (before touching pairs met at the stated film: its solves read the packer's
        clearance as a film, more of it in the converged boxes than in the cheap RVE)."""
        return self.provenance.get("contacts") != CONTACT_GEOMETRY

    @property
    def systems(self) -> dict[str, dict[str, Any]]:
        return dict(self.data["systems"])

    def why_not_for(self, system: MaterialSystem, cheap: RVESpec) -> str:
        """Empty where the table corrects ``cheap`` RVEs of ``system``; else one line why
        not. A table without a recorded material system (the one shipped) holds for the
        package's default system (the paper's)."""
        recorded = self.provenance.get("material_system")
        if recorded is None:
            if not is_default_system(system):
                return ("the shipped corrections hold for the paper's system (Al2O3 and AlN "
                        "in silicone, Table 1 sizes)")
        elif _solve_key(recorded) != _solve_key(system.to_dict()):
            return (f"the corrections file was built for the material system "
                    f"{recorded.get('name')!r} ({recorded.get('source')}), not this one")
        built = {k: v for k, v in self.provenance.get("cheap_rve", {}).items()
                 if k in RVESpec.field_names()}
        if built and RVESpec.from_dict(built) != cheap:
            return (f"the corrections correct a {built['box_um']:g} um cheap RVE at "
                    f"{built['voxel_um']:g} um, not this one ({cheap.box_um:g} um at "
                    f"{cheap.voxel_um:g} um)")
        return ""

    def for_fractions(self, fractions: Mapping[str, float]) -> ShippedFactor | None:
        """The correction of a formulation (filler -> volume fraction), or None where it is
        outside every studied system's range (another filler set, a hybrid not 1:1, a total
        fraction outside the studied one)."""
        fillers = sorted(fractions)
        total = float(sum(fractions.values()))
        if len(fillers) == 2 and abs(fractions[fillers[0]] - fractions[fillers[1]]) > \
                HYBRID_TOLERANCE:
            return None
        for name, s in self.systems.items():
            lo, hi = s["fraction_range"]
            if s["fillers"] == fillers and lo - 1e-9 <= total <= hi + 1e-9:
                own = tuple(p for p in self.data["points"] if p.get("system") == name
                            and sorted(p["fractions"]) == fillers
                            and all(abs(p["fractions"][f] - fractions[f]) < 1e-9
                                    for f in fillers))
                n_grid = math.prod(1 + (s["R_range"][q][1] > s["R_range"][q][0])
                                   for q in s["parameters"])
                return ShippedFactor(name, total, s, own if len(own) >= n_grid else (),
                                     STALE_CONTACTS_SD if self.stale_contacts else 0.0)
        return None

    def why_not(self, fractions: Mapping[str, float]) -> str:
        """One line: why a formulation has no shipped correction."""
        fillers = sorted(fractions)
        known = {n: s for n, s in self.systems.items() if s["fillers"] == fillers}
        if not known:
            return f"no shipped correction for the fillers {'+'.join(fillers)}"
        if len(fillers) == 2:
            return "the shipped hybrid corrections hold for 1:1 hybrids only"
        s = next(iter(known.values()))
        lo, hi = s["fraction_range"]
        return (f"total filler fraction {sum(fractions.values()):.3f} outside the studied "
                f"{lo:.2f}-{hi:.2f}")
