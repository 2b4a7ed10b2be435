"""The faithful correction (multi-fidelity) of the identification's forward models."""

from __future__ import annotations

import math

import numpy as np
import pytest
from refusals import refuses

from itr_fv.rve.spec import RVESpec
from itr_identify.forward.fidelity import (
    BIAS_ORDER,
    FIDELITY_LEVELS,
    FaithfulRVE,
    faithful_for,
    richardson,
)
from itr_identify.forward.model import ForwardSettings
from itr_identify.inference.measurements import read_measurements
from itr_identify.inference.pipeline import identify
from itr_identify.reporting.error_budget import error_budget, error_budget_lines


def test_richardson_recovers_the_limit_of_an_exact_power_law():
    k0, c, p = 1.6, 0.146, 1.29
    h, H = 0.2, 0.25
    fine, coarse = k0 * (1 - c * h ** p), k0 * (1 - c * H ** p)
    assert richardson(np.array([fine]), np.array([coarse]), H / h, p)[0] == pytest.approx(k0,
                                                                                         rel=1e-12)
    with refuses(ValueError, "ratio"):
        richardson(fine, coarse, 1.0, p)


@pytest.mark.parametrize("change, match", [
    ({"coarse_voxel_um": 0.2}, "coarse_voxel_um"),
    ({"boxes_um": (("Al2O3", 10.5),)}, "box_um/voxel_um"),
    ({"boxes_um": (("Al2O3", 10.1),)}, "box_um/voxel_um"),
    ({"packings": 1}, "packings"),
    ({"move_tolerance": 0.0}, "move_tolerance"),
    ({"boxes_um": ()}, "boxes_um"),
])
def test_bad_faithful_settings_name_the_argument(change, match):
    kw = {"boxes_um": (("Al2O3", 12.0),), "voxel_um": 0.2, "coarse_voxel_um": 0.25, **change}
    with refuses(ValueError, match):
        FaithfulRVE(**kw)


def test_fidelity_levels_are_named_and_checked():
    assert faithful_for("quick") is None
    for name in ("standard", "paper"):
        fa = faithful_for(name)
        assert fa.name == name and fa.voxel_um < fa.coarse_voxel_um
    assert FIDELITY_LEVELS["paper"].box_for(["Al2O3", "AlN"]) >= 40.0
    with refuses(ValueError, "fidelity"):
        faithful_for("best")
    with refuses(ValueError, "boxes_um"):
        FIDELITY_LEVELS["standard"].box_for(["BN"])


@pytest.fixture(scope="module")
def corrected():
    """Three Al2O3 formulations of Table 3: reduced bases on 10 um RVEs at 0.5 um, corrected
    on 12 um packings at 0.4 / 0.5 um."""
    meas = read_measurements()
    for f in list(meas.formulations):
        if f not in ("Al2O3-55", "Al2O3-58", "Al2O3-60"):
            meas = meas.without(f)
    fa = FaithfulRVE((("Al2O3", 12.0),), 0.4, 0.5)
    settings = ForwardSettings(RVESpec(box_um=10.0, voxel_um=0.5, seed=3), replicas=2,
                               faithful=fa)
    quick = identify(meas, "gap", settings=settings.with_(faithful=None), grid_points=41,
                     echo=lambda _: None)
    return identify(meas, "gap", settings=settings, grid_points=41, echo=lambda _: None), quick


@pytest.mark.slow
def test_correction_makes_the_model_the_faithful_estimate_at_its_point(corrected):
    ident, _ = corrected
    for f, m in ident.models.items():
        c = m.correction
        assert c is not None and len(c.seeds) == 2
        assert min(c.seeds) >= 9001          # packings the cheap replicas never use
        at = {p: np.array([v]) for p, v in c.at.items()}
        assert m.predict(at)[0][0] == pytest.approx(c.k_faithful, rel=1e-9)
        # the gap model's voxel bias is negative (finer voxels conduct better): the
        # extrapolated k lies above the fine voxel's, by the Richardson formula
        assert np.all(c.k_fine.mean(axis=1) > c.k_coarse.mean(axis=1))
        ratio = c.coarse_voxel_um / c.voxel_um
        expected = c.k_fine + (c.k_fine - c.k_coarse) / (ratio ** BIAS_ORDER - 1)
        assert np.allclose(c.extrapolated, expected)
        assert 0 < c.relative_sd < 0.1


@pytest.mark.slow
def test_corrections_repeat_until_the_best_point_stops_moving(corrected):
    ident, quick = corrected
    rounds = ident.fidelity_rounds
    assert rounds and rounds[-1]["converged"]
    assert all(m < 0.1 for m in rounds[-1]["moves"].values())
    # the 12 um box and the bias-free voxel conduct better than the 10 um / 0.5 um RVE:
    # the same data need a larger resistance
    assert ident.posterior.best["R_Al2O3_silicone"] > 2 * quick.posterior.best["R_Al2O3_silicone"]
    # each round corrected where the previous calibration put the best point
    for a, b in zip(rounds, rounds[1:]):
        assert b["at"] == a["best"]


@pytest.mark.slow
def test_error_budget_gives_every_source_and_its_effect_on_the_resistance(corrected):
    ident, _ = corrected
    b = error_budget(ident)
    for f, d in b["formulations"].items():
        items = d["items"]
        assert items["measurement noise"]["in_likelihood"]
        assert items["correction uncertainty"]["value"] == pytest.approx(
            ident.models[f].correction.relative_sd)
        assert items["faithful correction (applied)"]["value"] == pytest.approx(
            ident.models[f].fidelity_factor - 1)
        # shipped studies: a film lowers k, a larger box raises it
        assert items["film 5 nm"]["value"] < items["film 2 nm"]["value"] < 0
        assert items["box effect beyond the box solved"]["value"] > 0
    p = b["parameters"]["R_Al2O3_silicone"]
    assert -1 < p["dlnk_dlnR"] < 0
    # a film lowers the model's k: the same data then need a smaller resistance
    assert p["factors"]["film 5 nm"] < p["factors"]["film 2 nm"] < 1
    lo, hi = ident.posterior.interval("R_Al2O3_silicone")
    assert p["interval_half_width_factor"] == pytest.approx(math.sqrt(hi / lo))
    text = "\n".join(error_budget_lines(ident))
    assert "R_Al2O3_silicone" in text and "below the measurement noise" in text
