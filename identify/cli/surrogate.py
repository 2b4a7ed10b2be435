"""``itr surrogate fit|show``: surrogates of a campaign's results, stored without pickle.

- ``itr surrogate fit DIR --out model.json``: the prototypical-function model
  (:class:`itr_surrogate.prototype.PrototypeRegressor`) of k_iso over the parameters the
  campaign varies, for one formulation (all its RVE replicas);
- ``itr surrogate fit DIR --model reduced-basis --out model.npz``: the certified reduced
  basis (:class:`itr_surrogate.reduced_basis.ReducedBasis`) of one RVE of the campaign (rebuilt
  from its seed) over the box of the campaign's parameter values; it makes its own full
  solves;
- ``itr surrogate show FILE``: what a stored surrogate holds.

Errors are one line (:mod:`itr_identify.cli` prints them); status 2 for a bad flag, folder or
file.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from .core import CLIError, Parser, number, open_campaign

__all__ = ["add_parser"]

_MODELS = ("prototype", "reduced-basis")


def _formulation_rows(store, name: str | None):
    table = store.results()
    names = sorted(set(table.column("formulation").to_pylist()))
    if name is None:
        if len(names) > 1:
            raise CLIError(f"--formulation: the campaign holds {names}; name one", 2)
        name = names[0]
    else:
        from ..inference.formulations import formulation_name

        try:
            name = formulation_name(name, names)  # any letter case; a near miss suggested
        except ValueError as exc:
            hint = (f"; did you mean {exc.suggestion!r}?"
                    if getattr(exc, "suggestion", None) else "")
            raise CLIError(f"--formulation: {name!r} is not in the campaign (it holds "
                           f"{names}){hint}", 2) from None
    mask = np.array([f == name for f in table.column("formulation").to_pylist()])
    return name, table.filter(mask)


def _varied(camp, table) -> list[str]:
    """The campaign's parameters (flat names) that take more than one value in ``table``."""
    known = set(camp.base)
    for f in camp.formulations:
        for s in camp.parameter_sets(f):
            known.update(s)
    names = []
    for col in table.schema.names:
        if col not in known:
            continue
        values = np.asarray(table.column(col).to_numpy(), dtype=np.float64)
        if np.unique(values).size > 1:
            names.append(col)
    if not names:
        raise CLIError("DIR: the campaign varies no parameter; nothing to fit", 2)
    return names


def _fit(args: argparse.Namespace) -> int:
    from itr_fv.io import output_file
    from itr_surrogate.campaign import CampaignError

    store = open_campaign(args.dir)
    suffix = ".json" if args.model == "prototype" else ".npz"
    try:
        out = output_file(args.out, suffix, "--out")
    except ValueError as exc:
        raise CLIError(str(exc), 2) from None
    try:
        name, table = _formulation_rows(store, args.formulation)
    except CampaignError as exc:  # no finished rows yet
        raise CLIError(f"DIR: {exc}", 2) from None
    camp = store.campaign()
    features = _varied(camp, table)
    if args.model == "prototype":
        from itr_surrogate.prototype import PrototypeRegressor

        X = np.column_stack([np.asarray(table.column(f).to_numpy(), dtype=np.float64)
                             for f in features])
        y = np.asarray(table.column("k_iso").to_numpy(), dtype=np.float64)
        model = PrototypeRegressor(feature_names=features).fit(X, y)
        model.save(out)
        print(f"wrote {out}: prototype model of k_iso for {name} from {X.shape[0]} solves, "
              f"R^2 {model.r2_:.5f}")
        print(model.to_expression())
        return 0
    from itr_fv.discrete.problem import DiscreteProblem
    from itr_surrogate.reduced_basis import ReducedBasis
    from itr_surrogate.runner import campaign_rve

    replicas = sorted(set(table.column("replica").to_pylist()))
    if args.replica not in replicas:
        raise CLIError(f"--replica: {args.replica} is not solved in the campaign (it holds "
                       f"{replicas})", 2)
    bounds = {}
    for f in features:
        v = np.asarray(table.column(f).to_numpy(), dtype=np.float64)
        bounds[f] = (float(v.min()), float(v.max()))
    mid = {f: float(np.sqrt(lo * hi)) for f, (lo, hi) in bounds.items()}
    ms = campaign_rve(camp, name, args.replica).microstructure
    rb = ReducedBasis(DiscreteProblem(ms, contact=camp.contact), camp.materials(mid), bounds,
                      tol=args.tol, max_solves=args.max_solves, solver=camp.solver,
                      progress=not args.no_progress).fit()
    rb.save(out)
    print(f"wrote {out}: {rb!r}")
    return 0


def _show(args: argparse.Namespace) -> int:
    path = Path(args.file)
    if not path.is_file():
        raise CLIError(f"FILE: {args.file!r} is not a file", 2)
    if path.suffix.lower() == ".npz":
        from itr_surrogate.reduced_basis import ReducedBasis

        rb = ReducedBasis.load(path)
        info = rb.microstructure_info_
        print(f"reduced basis of one RVE ({'x'.join(map(str, info['shape']))} voxels of "
              f"{info['voxel_m'] * 1e6:g} um, contact {info['contact']})")
        for n, (lo, hi) in rb.box_.to_dict().items():
            print(f"  {n}: [{lo:g}, {hi:g}]")
        print(f"  {rb.n_solves_} full solves, training gap {rb.training_gap_:.2e} "
              f"(tol {rb.tol:g}, converged {rb.converged_}), {rb.n_interpolation_terms_} "
              f"interpolation terms (eps {rb.interpolation_error_:.1e})")
        return 0
    from itr_surrogate.prototype import PrototypeRegressor

    try:
        model = PrototypeRegressor.load(path)
    except (ValueError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CLIError(f"FILE: {args.file!r} is not a surrogate file ({exc})", 2) from None
    n = len(model.feature_names_in_)
    print(f"prototype model of {n} feature{'' if n == 1 else 's'} "
          f"({', '.join(model.feature_names_in_)}), training R^2 {model.r2_:.5f}")
    print(model.to_expression())
    return 0


def add_parser(sub) -> None:
    """Register ``surrogate fit|show`` on the ``itr`` subparsers ``sub``."""
    sur = sub.add_parser("surrogate", help="surrogates of a campaign (prototype, reduced basis)",
                         description="Fit a surrogate to a campaign's results and store it "
                         "(JSON or npz, no pickle); show a stored one.")
    actions = sur.add_subparsers(dest="action", required=True, parser_class=Parser)
    fit = actions.add_parser("fit", help="fit a surrogate to a campaign folder")
    fit.add_argument("dir", help="campaign folder (itr campaign run --out DIR)")
    fit.add_argument("--out", required=True, help="model file: .json (prototype) or .npz "
                     "(reduced-basis)")
    fit.add_argument("--model", choices=_MODELS, default="prototype",
                     help="prototype (default) or reduced-basis")
    fit.add_argument("--formulation", default=None,
                     help="formulation to fit, in any letter case (needed when the campaign "
                     "holds several)")
    fit.add_argument("--replica", type=number(int, 0, None, lo_open=False), default=0,
                     help="RVE replica of the reduced basis (default 0)")
    fit.add_argument("--tol", type=number(float, 1e-12, 0.5, lo_open=False), default=1e-3,
                     help="reduced basis: relative gap of its bounds (default 1e-3)")
    fit.add_argument("--max-solves", type=number(int, 0, 200, hi_open=False), default=40,
                     help="reduced basis: full solves at most (default 40)")
    fit.add_argument("--no-progress", action="store_true", help="no progress bar")
    fit.set_defaults(func=_fit)
    show = actions.add_parser("show", help="what a stored surrogate holds")
    show.add_argument("file", help="model file (.json or .npz)")
    show.set_defaults(func=_show)
