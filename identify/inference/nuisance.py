"""Inputs the forward model holds fixed, marginalised: the matrix and the filler
conductivities, and the film at which touching particles meet.

Every face conductance of the discrete model scales by ``lam`` when every conductivity does
and every resistance is divided by it, so exactly

    k_eff(lam k_m, lam k_f, R / lam) = lam k_eff(k_m, k_f, R),

and a matrix conductivity ``lam k_m`` with filler conductivities ``mu_f k_f`` gives

    k_eff(lam k_m, mu_f k_f, R) = lam k_eff(k_m, (mu_f / lam) k_f, lam R)
                                ~= lam prod_f (mu_f / lam)^(s_f) k_model(lam R),

``k_model`` the forward model at its nominal conductivities (reduced basis, replica factor,
correction) and ``s_f = d ln k_eff / d ln k_f`` the formulation's elasticity to filler f's
conductivity, measured by one full solve per filler (:func:`elasticities`: the first replica
at the best values with ``k_f`` times 0.8). The ``lam R`` part is exact; the filler part is
first order in ``ln(mu_f / lam)`` (s_f is 0.02 for AlN-60 and 0.12 for Al2O3-60 in the cheap
RVE: the filler's conductivity matters little behind its interface resistance). No full
solve is added per input value: the inputs enter through the models already built.

The film enters the same way, to first order: k_model times ``exp(s_film film)``, with
``s_film = d ln k_eff / d film`` (1/nm) the secant from the models' film 0 to
:data:`FILM_STEP_NM` on the first replica's particles (one full solve per formulation); k
falls about linearly with the film over 0-5 nm (``validation/results/contact_film.md``:
k(1) / k(0) 0.991, k(2) / k(0) 0.983, k(5) / k(0) 0.960 for Al2O3-60), so the secant is
within a few 0.1 % of k over the range. Its prior (:class:`FilmPrior`) is uniform over a
range of films (default 0-5 nm), integrated by :data:`FILM_NODES` Gauss-Legendre nodes.

Each conductivity has a lognormal prior (:class:`InputPrior`: nominal value and relative standard
deviation; :func:`default_priors`: the material system's, argued for the paper's in
``docs/identification.md``). The posterior of
the resistances with the inputs integrated out is a mixture over a Gauss-Hermite product
grid of the inputs' log values (:data:`NODES` per input): each node a full calibration
(:func:`~itr_identify.inference.calibrate.calibrate`, the same grid in R), weighted by its
quadrature weight times its evidence (:attr:`Posterior.log_evidence`: how well the data
like those input values). Samples of the marginal posterior are drawn from the nodes by
weight; its best values are its own central point
(:meth:`~itr_identify.inference.calibrate.Posterior.central`: the sample nearest the
marginal medians), not the nominal node's, which can sit at an end of the marginal interval
when the data prefer other inputs. The nominal calibration stays where the models are
checked at the inputs they were built at (``Identification.at_nominal``). The variance of
each log10 resistance splits into the part the data leave at fixed inputs
(``measurements``) and one share per input (the weighted regression of the nodes' posterior
means on the inputs' standardised log values, scaled to sum to the between-node part: the
shares and ``measurements`` sum to 1).
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from itr_fv.materials.material_system import MaterialSystem
from itr_fv.materials.parameters import parse_parameter

from ..forward.model import ForwardModel
from .calibrate import Posterior, calibrate
from .measurements import Measurements

__all__ = [
    "DEFAULT_FILM",
    "NODES",
    "FilmPrior",
    "InputPrior",
    "MarginalisationRecord",
    "ScaledModel",
    "default_priors",
    "elasticities",
    "marginalise",
    "narrowing",
]

#: Gauss-Hermite nodes per input (the matrix first; a filler's conductivity, whose
#: elasticity is small, takes :data:`FILLER_NODES`).
NODES = 5
FILLER_NODES = 3
#: k_f of the elasticity's solve, relative to nominal.
ELASTICITY_STEP = 0.8
#: Relative residual of the elasticity's two solves: a difference quotient needs its solves
#: far tighter than the difference (ln 0.8 s_f is a few 1e-3).
ELASTICITY_TOL = 1e-11
#: Gauss-Legendre nodes of the film's uniform prior.
FILM_NODES = 3
#: The film of the film elasticity's solve, nm (the middle of the default prior: a secant
#: over it, k falling about linearly with the film there, ``contact_film.md``).
FILM_STEP_NM = 2.5
#: Grid points per parameter of a node's calibration other than the nominal one (the
#: mixture is a quadrature of the inputs; each node's own interval needs no finer grid).
NODE_GRID_POINTS = 61


@dataclass(frozen=True)
class InputPrior:
    """A lognormal prior of one conductivity.

    Attributes
    ----------
    name : str
        Flat parameter name, ``k_<phase>``.
    nominal : float
        Median, W/(m K) (the value the forward models were built at unless stated).
    rel_sd : float
        Standard deviation of its natural log (>= 0; 0: held at nominal).
    """

    name: str
    nominal: float
    rel_sd: float

    def __post_init__(self) -> None:
        kind, _ = parse_parameter(self.name)
        if kind != "k":
            raise ValueError(f"name: expected a conductivity k_<phase>, got {self.name!r}")
        if not (isinstance(self.nominal, (int, float)) and self.nominal > 0
                and math.isfinite(self.nominal)):
            raise ValueError(f"{self.name}: expected a conductivity > 0 W/(m K), got "
                             f"{self.nominal!r}")
        if not (isinstance(self.rel_sd, (int, float)) and 0 <= self.rel_sd <= 1):
            raise ValueError(f"{self.name} sd: expected a relative standard deviation in "
                             f"[0, 1], got {self.rel_sd!r}")

    @property
    def phase(self) -> str:
        return parse_parameter(self.name)[1][0]


@dataclass(frozen=True)
class FilmPrior:
    """A uniform prior of the silicone film at which touching particles meet.

    Attributes
    ----------
    low_nm, high_nm : float
        Its range, nm (0 <= low < high <= 20); the forward models are built at film 0.
    """

    low_nm: float = 0.0
    high_nm: float = 5.0
    name: str = "film_nm"

    def __post_init__(self) -> None:
        for key in ("low_nm", "high_nm"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 20):
                raise ValueError(f"film {key}: expected a film in [0, 20] nm, got {v!r}")
        if not self.low_nm < self.high_nm:
            raise ValueError(f"film: expected low_nm < high_nm, got {self.low_nm!r}, "
                             f"{self.high_nm!r}")


#: The film's default prior: uniform over 0-5 nm (``docs/identification.md``: the range the
#: contact-film table measures; k falls 4-5 % over it).
DEFAULT_FILM = FilmPrior()


def default_priors(phases: Sequence[str], system: MaterialSystem) -> dict[str, InputPrior]:
    """The default prior of every phase of ``phases``: the material system's nominal
    conductivity and relative sd (:meth:`MaterialSystem.conductivity_sds`; the paper's
    system: an unmeasured neat silicone 10 %, alumina powder 15 %, aluminium nitride powder
    25 %, see ``docs/identification.md``; a system file's: its stated sd or range, else the
    handbook's range)."""
    k = system.conductivities()
    sd = system.conductivity_sds()
    return {f"k_{p}": InputPrior(f"k_{p}", float(k[p]), float(sd[p])) for p in phases}


class ScaledModel:
    """A forward model at other conductivities (the module's scaling): what
    :func:`~itr_identify.inference.calibrate.calibrate` reads of a model, the rest passed
    through."""

    def __init__(self, model: ForwardModel, lam: float, mu: Mapping[str, float],
                 elasticity: Mapping[str, float], film_nm: float = 0.0):
        self.model = model
        self.lam = float(lam)
        f = self.lam
        for filler in model.fractions:
            f *= (float(mu.get(filler, 1.0)) / self.lam) ** float(elasticity.get(filler, 0.0))
        self.factor = f * math.exp(float(elasticity.get("film_nm", 0.0)) * float(film_nm))

    def __getattr__(self, name: str):
        return getattr(self.model, name)

    def predict(self, columns: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        k, err = self.model.predict({p: np.asarray(v, dtype=float) * self.lam
                                     for p, v in columns.items()})
        return k * self.factor, err * self.factor


def elasticities(models: Mapping[str, ForwardModel], values: Mapping[str, float], *,
                 film: bool = False) -> dict[str, dict[str, float]]:
    """Per formulation and filler: d ln k_eff / d ln k_f at ``values`` (m^2 K/W), from full
    solves of the first replica at nominal and with k_f times :data:`ELASTICITY_STEP`, all to
    the relative residual :data:`ELASTICITY_TOL`; with ``film``, also ``film_nm``: d ln k_eff
    / d film (1/nm), the secant from film 0 to :data:`FILM_STEP_NM` on the same particles."""
    out = {}
    for f, m in models.items():
        k = m.settings.system.conductivities()
        own = {p: values[p] for p in m.parameters if p in values}
        base = float(m.solve_first(own, purpose="conductivity elasticity",
                                   tol=ELASTICITY_TOL).mean())
        out[f] = {}
        for filler in m.fractions:
            scaled = {**own, f"k_{filler}": ELASTICITY_STEP * float(k[filler])}
            low = float(m.solve_first(scaled, purpose="conductivity elasticity",
                                      tol=ELASTICITY_TOL).mean())
            out[f][filler] = math.log(low / base) / math.log(ELASTICITY_STEP)
        if film:
            thin = float(m.solve_first(own, purpose="film elasticity", tol=ELASTICITY_TOL,
                                       film_m=FILM_STEP_NM * 1e-9).mean())
            out[f]["film_nm"] = math.log(thin / base) / FILM_STEP_NM
    return out


def _system_of(models: Mapping[str, ForwardModel]) -> MaterialSystem:
    """The one material system the models were built in (ValueError if they differ)."""
    systems = {id(m.settings.system): m.settings.system for m in models.values()}
    first = next(iter(systems.values()))
    if any(s != first for s in systems.values()):
        raise ValueError("models: built in different material systems")
    return first


def _nodes(priors: Sequence[InputPrior | FilmPrior]) -> tuple[np.ndarray, np.ndarray]:
    """Standardised nodes (J, inputs) and log weights (J,) of the product grid (a film: its
    nodes in [-1, 1] over its range)."""
    axes, logw = [], []
    for i, pr in enumerate(priors):
        if isinstance(pr, FilmPrior):
            x, w = np.polynomial.legendre.leggauss(FILM_NODES)
        else:
            n = NODES if i == 0 else FILLER_NODES
            if pr.rel_sd == 0:
                n = 1
            x, w = np.polynomial.hermite_e.hermegauss(n)
        axes.append(x)
        logw.append(np.log(w / w.sum()))
    z = np.array(list(itertools.product(*axes))).reshape(-1, len(priors))
    lw = np.array([sum(c) for c in itertools.product(*logw)]) if priors else np.zeros(1)
    return z, lw


@dataclass(frozen=True)
class MarginalisationRecord:
    """What :func:`marginalise` found besides the posterior (frozen; :meth:`to_dict` is the
    JSON-ready form that ``Identification.inputs`` holds).

    Attributes
    ----------
    inputs : dict
        Per input its prior: ``nominal`` (W/(m K)) and ``rel_sd`` of a conductivity,
        ``low_nm`` and ``high_nm`` of a film.
    nodes : int
        Nodes of the quadrature (full calibrations).
    parameters : dict
        Per parameter: ``interval_nominal`` and ``interval_marginal`` (m^2 K/W, 90 %),
        ``shares`` (each input's share of the variance of its log10 value, with
        ``measurements``: they sum to 1) and ``if_known`` (per input, the 90 % interval
        with that input known exactly, m^2 K/W).
    node_weights : list of float
        The nodes' posterior weights (summing to 1).
    """

    inputs: dict[str, dict[str, float]]
    nodes: int
    parameters: dict[str, dict]
    node_weights: list[float]

    def to_dict(self) -> dict:
        """The record as JSON-ready data (a copy), in the order of the attributes."""
        return copy.deepcopy({"inputs": self.inputs, "nodes": self.nodes,
                              "parameters": self.parameters,
                              "node_weights": self.node_weights})


def marginalise(models: Mapping[str, ForwardModel], measurements: Measurements,
                nominal: Posterior, priors: Mapping[str, InputPrior | FilmPrior], *,
                elasticity: Mapping[str, Mapping[str, float]],
                n_samples: int = 4000, seed: int = 0,
                **calibrate_kw) -> tuple[Posterior, MarginalisationRecord]:
    """The posterior with the conductivities of ``priors`` integrated out.

    Parameters
    ----------
    models, measurements
        As for :func:`~itr_identify.inference.calibrate.calibrate`.
    nominal : Posterior
        The calibration at the nominal inputs (its ``model_form_sd`` is kept at every node).
    priors : mapping of name to InputPrior or FilmPrior
        The inputs to integrate out (``k_<matrix>`` and ``k_<filler>``; ``film_nm``, a
        :class:`FilmPrior`, where the models were built at film 0); the conductivities'
        nominal values must be those the models were built at.
    elasticity : mapping
        :func:`elasticities` of the models (with ``film_nm`` where the film is integrated
        out).
    n_samples, seed : int
        Samples of the marginal posterior drawn from the nodes, and their seed.
    **calibrate_kw
        Passed to every node's :func:`~itr_identify.inference.calibrate.calibrate` (its
        ``grid_points`` at most :data:`NODE_GRID_POINTS` away from the nominal node).

    Returns
    -------
    (Posterior, MarginalisationRecord)
        The marginal posterior (its best values its own central point) and the record:
        per input its prior, per parameter the interval at nominal inputs, the marginal one
        and each input's share of the variance of its log10 value, and the nodes' weights.
    """
    system = _system_of(models)
    prs = _ordered_priors(priors, system, elasticity)
    z, logw = _nodes(prs)
    posts = [_node_posterior(models, measurements, nominal, prs, row, system=system,
                             elasticity=elasticity, seed=seed, calibrate_kw=calibrate_kw)
             for row in z]
    lpw = np.array([lw + post.log_evidence for lw, post in zip(logw, posts)])
    w = np.exp(lpw - lpw.max())
    w /= w.sum()
    rng = np.random.default_rng(seed)
    names = nominal.names
    samples = _mixture_draws(posts, w, names, rng, n_samples)
    marginal = Posterior(list(names), samples, {}, nominal.prior, stages=nominal.stages,
                         model_form_sd=nominal.model_form_sd,
                         log_evidence=float(lpw.max() + math.log(np.exp(lpw - lpw.max()).sum())))
    marginal = replace(marginal, best=marginal.central())
    input_names = [pr.name for pr in prs]
    record = MarginalisationRecord(
        inputs={pr.name: ({"low_nm": pr.low_nm, "high_nm": pr.high_nm}
                          if isinstance(pr, FilmPrior) else
                          {"nominal": pr.nominal, "rel_sd": pr.rel_sd})
                for pr in prs},
        nodes=len(posts),
        parameters={n: _parameter_record(n, posts, w, z, input_names, nominal=nominal,
                                         marginal=marginal, seed=seed)
                    for n in names},
        node_weights=w.tolist())
    return marginal, record


def _ordered_priors(priors: Mapping[str, InputPrior | FilmPrior], system: MaterialSystem,
                    elasticity: Mapping[str, Mapping[str, float]]
                    ) -> list[InputPrior | FilmPrior]:
    """The priors in quadrature order (the matrix's conductivity first, then the fillers',
    the film last), checked against the models: a film needs every model's film
    elasticity, a conductivity its nominal value the one the models were built at
    (ValueError naming what is missing or off)."""
    k0 = system.conductivities()
    matrix = system.matrix
    order = sorted(priors, key=lambda n: (isinstance(priors[n], FilmPrior),
                                          n != f"k_{matrix}", n))
    prs = [priors[n] for n in order]
    if any(isinstance(pr, FilmPrior) for pr in prs) and any(
            "film_nm" not in e for e in elasticity.values()):
        raise ValueError("elasticity: a film prior needs the film elasticity of every model "
                         "(elasticities(..., film=True))")
    for pr in prs:
        if isinstance(pr, FilmPrior):
            continue
        if not math.isclose(pr.nominal, float(k0[pr.phase]), rel_tol=1e-12):
            raise ValueError(f"{pr.name}: the forward models were built at "
                             f"{float(k0[pr.phase]):g} W/(m K); a prior centred elsewhere "
                             f"({pr.nominal:g}) needs models built there")
    return prs


def _node_posterior(models: Mapping[str, ForwardModel], measurements: Measurements,
                    nominal: Posterior, prs: Sequence[InputPrior | FilmPrior],
                    row: np.ndarray, *, system: MaterialSystem,
                    elasticity: Mapping[str, Mapping[str, float]], seed: int,
                    calibrate_kw: Mapping[str, Any]) -> Posterior:
    """The calibration at one node ``row`` of the quadrature (standardised inputs, in the
    order of ``prs``): ``nominal`` itself at the nominal node, else the models scaled to
    the node's inputs (:class:`ScaledModel`) calibrated on at most
    :data:`NODE_GRID_POINTS` points per parameter."""
    k0 = system.conductivities()
    matrix = system.matrix
    value = {pr.name: _value(pr, x) for pr, x in zip(prs, row)}
    lam = value.get(f"k_{matrix}", k0[matrix]) / k0[matrix]
    mu = {pr.phase: value[pr.name] / pr.nominal for pr in prs
          if isinstance(pr, InputPrior) and pr.phase != matrix}
    film_nm = value.get("film_nm", 0.0)
    if np.all(row == 0) and film_nm == 0:
        return nominal
    scaled = {f: ScaledModel(m, lam, mu, elasticity.get(f, {}), film_nm)
              for f, m in models.items()}
    kw = {**calibrate_kw, "grid_points": min(calibrate_kw.get("grid_points", 121),
                                             NODE_GRID_POINTS)}
    return calibrate(scaled, measurements, model_form_sd=nominal.model_form_sd, seed=seed,
                     **kw)


def _mixture_draws(posts: Sequence[Posterior], w: np.ndarray, names: Sequence[str],
                   rng: np.random.Generator, n_samples: int) -> np.ndarray:
    """``n_samples`` draws (log10 values, columns ``names``) of the mixture of the nodes'
    posteriors ``posts`` weighted ``w``: a node per draw by weight, then as many of its
    samples at random."""
    pick = rng.choice(len(posts), size=n_samples, p=w)
    cols = [[p.names.index(n) for n in names] for p in posts]
    return np.vstack([posts[j].samples[rng.integers(0, posts[j].samples.shape[0],
                                                     int(np.sum(pick == j))), :][:, cols[j]]
                      for j in range(len(posts)) if np.any(pick == j)])


def _parameter_record(name: str, posts: Sequence[Posterior], w: np.ndarray, z: np.ndarray,
                      input_names: Sequence[str], *, nominal: Posterior, marginal: Posterior,
                      seed: int) -> dict:
    """One parameter's entry of :attr:`MarginalisationRecord.parameters`: its nominal and
    marginal intervals, the variance shares (the inputs' part scaled to the between-node
    variance, ``measurements`` the within-node part) and the interval with each input
    known."""
    means = np.array([float(np.mean(p.samples[:, p.names.index(name)])) for p in posts])
    within = np.array([float(np.var(p.samples[:, p.names.index(name)])) for p in posts])
    total = float(np.sum(w * (within + (means - np.sum(w * means)) ** 2)))
    shares = _shares(z, w, means, total, list(input_names))
    measured = float(np.sum(w * within)) / total if total > 0 else 1.0
    explained = sum(shares.values())
    if explained > 0:   # the inputs' part is the between-node variance: 1 - measured
        shares = {k: v * (1.0 - measured) / explained for k, v in shares.items()}
    shares["measurements"] = measured
    if_known = {n: _mixture_interval(posts, w * (z[:, i] == 0), name, nominal, seed)
                for i, n in enumerate(input_names)}
    return {"interval_nominal": list(nominal.interval(name)),
            "interval_marginal": list(marginal.interval(name)),
            "shares": shares, "if_known": if_known}


def _value(prior: InputPrior | FilmPrior, x: float) -> float:
    """An input's value at the standardised node ``x`` (W/(m K), or nm for a film)."""
    if isinstance(prior, FilmPrior):
        return prior.low_nm + (x + 1.0) / 2.0 * (prior.high_nm - prior.low_nm)
    return prior.nominal * math.exp(prior.rel_sd * x)


def _mixture_interval(posts: Sequence[Posterior], w: np.ndarray, name: str,
                      nominal: Posterior, seed: int, n_samples: int = 4000) -> list[float]:
    """The 90 % interval (m^2 K/W) of ``name`` over the nodes weighted ``w`` (an input known
    exactly: only its nominal nodes, their weights renormalised)."""
    w = w / w.sum()
    rng = np.random.default_rng(seed + 1)
    pick = rng.choice(len(posts), size=n_samples, p=w)
    x = np.concatenate([posts[j].samples[rng.integers(0, posts[j].samples.shape[0],
                                                       int(np.sum(pick == j))),
                                         posts[j].names.index(name)]
                        for j in range(len(posts)) if np.any(pick == j)])
    post = Posterior([name], x[:, None], {}, nominal.prior)
    return list(post.interval(name))


def narrowing(record: Mapping, name: str) -> list[dict]:
    """The inputs of a :func:`marginalise` record ranked by how much knowing each exactly
    would narrow the 90 % interval of ``name``: ``input``, ``interval`` (m^2 K/W) and
    ``factor`` (the interval's half-width as a factor, ``sqrt(hi / lo)``)."""
    par = record["parameters"][name]
    rows = [{"input": k, "interval": v, "factor": math.sqrt(v[1] / v[0])}
            for k, v in par["if_known"].items()]
    return sorted(rows, key=lambda r: r["factor"])


def _shares(z: np.ndarray, w: np.ndarray, means: np.ndarray, total: float,
            names: Sequence[str]) -> dict[str, float]:
    """Each input's share of the variance ``total`` of a log10 parameter: the weighted
    least-squares slopes of the nodes' means on the standardised inputs, times the inputs'
    weighted variances (the between-node part the inputs explain, one term each)."""
    if total <= 0 or z.shape[0] < 2:
        return {n: 0.0 for n in names}
    X = np.column_stack([np.ones(z.shape[0]), z])
    sw = np.sqrt(w)
    beta, *_ = np.linalg.lstsq(X * sw[:, None], means * sw, rcond=None)
    out = {}
    for i, n in enumerate(names):
        zi = z[:, i]
        var = float(np.sum(w * (zi - np.sum(w * zi)) ** 2))
        out[n] = float(beta[i + 1] ** 2 * var / total)
    return out
