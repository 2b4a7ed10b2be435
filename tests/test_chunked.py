"""The chunked evaluation on threads (identify/inference/chunked.py): the same numbers as one
serial pass, in the same order, and the marginal built on it unchanged by the threads."""

from __future__ import annotations

import numpy as np
import pytest
from refusals import refuses

from itr_identify.inference import chunked, marginal
from itr_identify.inference.chunked import map_chunks


def _f(x):
    return np.sin(x[:, 0]) * np.exp(-x[:, 1] ** 2) + x.sum(axis=1)


def test_chunks_come_back_in_order_and_equal_a_serial_pass():
    x = np.random.default_rng(0).normal(size=(10_001, 3))
    serial = _f(x)
    for workers in (1, 2, 3):
        got = np.concatenate(list(map_chunks(_f, x, chunk=997, workers=workers)))
        np.testing.assert_array_equal(got, serial)
    with refuses(ValueError, "chunk"):
        list(map_chunks(_f, x, chunk=0))


def test_a_marginal_is_the_same_on_one_thread_and_on_several(monkeypatch):
    """A correlated Gaussian's marginal of its first coordinate: standard deviation 1
    (the conditional has sd sqrt(1 - rho^2) = 0.6, the draws spread its centre), and the
    same density whatever the threads."""
    rng = np.random.default_rng(1)
    cov = np.array([[1.0, 0.8], [0.8, 1.0]])
    inv = np.linalg.inv(cov)
    draws = rng.multivariate_normal([0, 0], cov, size=3000)

    def log_post(t):
        return -0.5 * np.einsum("ni,ij,nj->n", t, inv, t)

    monkeypatch.setattr(chunked, "threads", lambda: 1)
    one = marginal.rao_blackwell(log_post, draws, 0, lo=-6, hi=6)
    monkeypatch.setattr(chunked, "threads", lambda: 2)
    two = marginal.rao_blackwell(log_post, draws, 0, lo=-6, hi=6)
    np.testing.assert_array_equal(one.density, two.density)
    sd = np.sqrt(np.trapezoid(one.x ** 2 * one.density, one.x))
    assert sd == pytest.approx(1.0, abs=0.04)
