"""Faithful corrections shipped with the package: ``c = k_faithful / k_cheap`` as data.

The factor that takes the cheap RVE's conductivity (:data:`~itr_identify.forward.fidelity.
CHEAP_RVE`, the level the reduced basis stands for) to the converged box's with the voxel
bias removed depends on the formulation and the resistances, not on the measurements. It is
computed once from the campaigns of a corrections plan
(:mod:`itr_identify.forward.correction_plan`; assembled by
:mod:`itr_identify.forward.corrections_table`) and shipped as
``identify/data/corrections.json`` with its provenance.

:class:`ShippedCorrections` reads such a table; :meth:`ShippedCorrections.for_fractions`
gives a formulation's :class:`ShippedFactor`: per row of resistances the factor ``c``, the
relative standard uncertainty that is the formulation's own (the packings' scatter, with its
degrees of freedom, and the interpolation's) and the one its whole system shares (the box
step, the voxel bias and the tail cut: one term that moves every formulation of the system
together; the likelihood marginalises it once per system,
:mod:`itr_identify.inference.calibrate`). A formulation within a studied system's fraction
range (a hybrid: 1:1) has one; outside that, None, and the identification falls back to
runtime corrections. Resistances beyond the design's range take the nearest design value's
factor, and the fitted slope over the distance is added to the uncertainty.
"""

from __future__ import annotations

import json
import math
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

from .corrections_table import TABLE_FORMAT

__all__ = ["ShippedCorrections", "ShippedFactor", "SHIPPED_FILE"]

SHIPPED_FILE = "corrections.json"
#: How far a hybrid may be from 1:1 (difference of the two fractions) and still use the 1:1
#: fit, volume fraction.
HYBRID_TOLERANCE = 0.005


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

    def _columns(self, columns: Mapping[str, np.ndarray], n: int) -> tuple[dict, np.ndarray]:
        """Per parameter the values clipped into the design's range (m^2 K/W), and the
        distance beyond it (log10)."""
        f = self.fit
        clipped, beyond = {}, []
        for name in f["parameters"]:
            lo, hi = f["R_range"][name]
            v = np.broadcast_to(np.asarray(columns.get(name, f["R0"][name]), float), (n,))
            clipped[name] = np.clip(v, lo, hi)
            beyond.append(np.abs(np.log10(clipped[name] / v)))
        return clipped, np.array(beyond).reshape(len(clipped), n)

    def parts(self, columns: Mapping[str, np.ndarray], n: int) -> dict[str, Any]:
        """Per row of ``columns`` (m^2 K/W; a parameter not given sits at the design's
        centre): ``c``; the formulation's own relative uncertainties, ``packing`` (its
        ``packing_dof`` degrees of freedom) and ``interpolation`` (the local or system
        fit's residual, and the slope times the distance beyond the design); ``shared``,
        the system's term (each (n,))."""
        from .corrections_table import design_columns

        f = self.fit
        cols, beyond = self._columns(columns, n)
        if self.own:
            coef, interp = _local_fit(self.own, f)
            X = design_columns(f, self.fraction, cols, n, own=True)
            packing = math.sqrt(np.mean([p["packing_sd"] ** 2 for p in self.own]))
        else:
            coef, interp = np.asarray(f["coefficients"]), f["fit_rms"]
            X = design_columns(f, self.fraction, cols, n)
            packing = f["packing_sd"]
        c = X @ coef
        # the slope at the design's edge times the distance beyond it
        k = len(f["parameters"])
        slopes = np.abs(np.asarray(coef)[(1 if self.own else 2):(1 if self.own else 2) + k])
        extra = np.sqrt(np.sum((slopes[:, None] * beyond) ** 2, axis=0)) / np.maximum(c, 1e-12)
        return {"c": c, "packing": np.full(n, packing), "packing_dof": int(f["packing_dof"]),
                "interpolation": np.hypot(interp, extra),
                "shared": self.shared_sd(cols, n)}

    def shared_sd(self, columns: Mapping[str, np.ndarray], n: int) -> np.ndarray:
        """The system's shared relative sd per row (the box step's, the tail cut's and the
        voxel bias's at the mean log10 of the row's resistances), (n,)."""
        sh = self.fit["shared"]
        names = self.fit["parameters"]
        x = np.mean([np.log10(np.broadcast_to(np.asarray(columns.get(p, self.fit["R0"][p]),
                                                         float), (n,))) for p in names], axis=0)
        pts = sorted(sh["voxel"]["points"],
                     key=lambda q: np.mean([math.log10(v) for v in q["values"].values()]))
        xs = [np.mean([math.log10(v) for v in q["values"].values()]) for q in pts]
        sd_b = np.interp(x, xs, [q["sd"] for q in pts])
        return np.sqrt(sh["box"]["sd"] ** 2 + sh["tail"]["sd"] ** 2 + sd_b ** 2)

    def factor(self, columns: Mapping[str, np.ndarray], n: int) -> tuple[np.ndarray,
                                                                         np.ndarray]:
        """(c, the formulation's own relative standard uncertainty), each (n,), for
        ``{name: values}`` columns (m^2 K/W): its packings' and the interpolation's in
        quadrature; the system's shared term is :meth:`shared_sd`."""
        p = self.parts(columns, n)
        return p["c"], np.hypot(p["packing"], p["interpolation"])


def _local_fit(points: tuple[dict, ...], fit: Mapping[str, Any]) -> tuple[np.ndarray, float]:
    """Coefficients of a formulation's own quadratic in ``x_i = log10(R_i / R0_i)``
    (:func:`~itr_identify.forward.corrections_table.design_columns` with ``own``) through
    its design points by least squares, and their residual RMS (0 where exact)."""
    from .corrections_table import design_columns

    names = fit["parameters"]
    X = design_columns(fit, 0.0, {n: np.array([p["values"][n] for p in points])
                                  for n in names}, len(points), own=True)
    y = np.array([p["c"] for p in points])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    dof = len(y) - X.shape[1]
    return coef, float(math.sqrt(resid @ resid / dof)) if dof > 0 else 0.0


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
        if self.provenance.get("format", 1) < TABLE_FORMAT or self.stale_contacts:
            return (f"the corrections file {self.provenance.get('plan')!r} was built by an "
                    f"earlier plan (format {self.provenance.get('format', 1)}, contacts "
                    f"{self.provenance.get('contacts', 'the packer clearance')!r}); rebuild it "
                    "with 'itr corrections build'")
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
                # a formulation's own quadratic needs as many points as it has terms
                terms = 3 if len(s["parameters"]) == 1 else 6
                return ShippedFactor(name, total, s, own if len(own) >= terms else ())
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
