"""The discrete operator of :mod:`itr_fv.discrete.model` on a grid of face conductances: load
vectors, ``A theta``, face fluxes, the mean flux and the energy estimate of the effective
tensor.

Every function takes the face conductances ``g`` (W/(m^2 K), shape (3, n1, n2, n3),
``g[d][p]`` on the face between voxel p and p + e_d) that an interface law
(:mod:`itr_fv.discrete.interface_law`) produced, so every solver shares them.

The functions are written once against the Python array API standard (the namespace comes
from :func:`array_api_compat.array_namespace` of the arguments; only ``roll``, ``sum``,
``astype``, ``zeros``/``empty``, indexing and arithmetic are used): NumPy arrays on the host
and CuPy, PyTorch or ``array-api-strict`` arrays run the same lines, so a backend whose
arrays live on a GPU builds its load vectors and computes the mean flux and the energy tensor
there. Results come back where the arrays live, except the tensors and mean fluxes (a few
floats, host NumPy). Reductions are float64 whatever the precision of the arrays.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from array_api_compat import array_namespace
from array_api_compat import device as device_of

__all__ = ["cell_centres", "load_vector", "apply_operator", "face_differences", "face_fluxes",
           "mean_flux", "energy_tensor", "effective_tensors"]


def cell_centres(shape: tuple[int, int, int], voxel_m: float, axis: int) -> np.ndarray:
    """Coordinate (m) of the voxel centres along ``axis``, broadcastable to ``shape``."""
    x = (np.arange(shape[axis]) + 0.5) * voxel_m
    view = [1, 1, 1]
    view[axis] = shape[axis]
    return x.reshape(view)


def _float64(xp: Any, a: Any) -> Any:
    """``a`` in float64 (itself, not a copy, when it already is)."""
    return xp.astype(a, xp.float64, copy=False)


def _total(xp: Any, a: Any) -> float:
    """Sum of all entries of ``a`` in float64, as a host float (the one device sync)."""
    return float(xp.sum(_float64(xp, a)))


def _check_load(E: Sequence[float]) -> tuple[float, float, float]:
    try:
        load = tuple(float(e) for e in E)
    except (TypeError, ValueError):
        raise ValueError(f"E: expected 3 numbers (K/m), got {E!r}") from None
    if len(load) != 3:
        raise ValueError(f"E: expected 3 numbers (K/m), got {len(load)}")
    return load


def load_vector(g: Any, voxel_m: float, E: Sequence[float]) -> Any:
    """Right-hand side b(E) of ``A theta = b`` for the macroscopic gradient load E.

    With T = -E.x + theta and the outgoing face flux g (T_p - T_q), conservation in voxel p
    gives ``(A theta)_p = h * sum_d E_d (g_d[p - e_d] - g_d[p])``: a net flux density,
    W/m^2 for E in K/m (every term of the balance is divided by the face area h^2).

    Parameters
    ----------
    g : array, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K), in any array API library (the load vector is built
        where they live).
    voxel_m : float
        Voxel edge h, m.
    E : sequence of 3 floats
        Load, K/m (E = e_j gives column j of the effective tensor).

    Returns
    -------
    b : array, shape (n1, n2, n3), float64, in the namespace and on the device of ``g``
    """
    xp = array_namespace(g)
    load = _check_load(E)
    b = xp.zeros(g.shape[1:], dtype=xp.float64, device=device_of(g))
    for d in range(3):
        if load[d] != 0.0:
            gd = _float64(xp, g[d, ...])
            b += (voxel_m * load[d]) * (xp.roll(gd, 1, axis=d) - gd)
    return b


def apply_operator(g: Any, theta: Any, out: Any = None) -> Any:
    """``A theta``: net outgoing flux of every voxel for the periodic field theta (W/m^2).

    ``(A theta)_p = sum_d g_d[p] (theta_p - theta_{p+e_d}) - g_d[p-e_d] (theta_{p-e_d} -
    theta_p)``: the 7-point stencil of the face conductances, the one written in array code
    for every backend (the numba backend also has a fused kernel of it), computed in the
    precision of ``g`` and ``theta`` (no float64 promotion: CG's operator in float32 stays
    float32).

    Parameters
    ----------
    g : array, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    theta : array, shape (n1, n2, n3)
        Periodic temperature field, K.
    out : array, optional
        Written in place with the result (shape of ``theta``).

    Returns
    -------
    array, shape (n1, n2, n3)
        ``out`` when given, else a new array.
    """
    xp = array_namespace(g, theta)
    for d in range(3):
        up = g[d, ...] * (theta - xp.roll(theta, -1, axis=d))
        if d == 0:
            if out is None:
                out = up
            else:
                out[...] = up
        else:
            out += up
        out -= xp.roll(up, 1, axis=d)
    return out


def face_differences(theta: Any, axis: int, voxel_m: float, E_axis: float) -> Any:
    """Temperature drop across the faces normal to ``axis``, K, float64.

    ``T_p - T_{p+e_d} = theta_p - theta_{p+e_d} + h E_d`` with ``T = -E.x + theta``.

    Parameters
    ----------
    theta : array, shape (n1, n2, n3)
        Periodic fluctuation, K.
    axis : int
        Face normal d (0, 1, 2).
    voxel_m : float
        Voxel edge h, m.
    E_axis : float
        Component E_d of the load, K/m.
    """
    xp = array_namespace(theta)
    t = _float64(xp, theta)
    dT = t - xp.roll(t, -1, axis=axis)
    if E_axis != 0.0:
        dT += voxel_m * E_axis
    return dT


def face_fluxes(g: Any, theta: Any, voxel_m: float, E: Sequence[float]) -> Any:
    """Flux density through every face, W/m^2, shape (3, n1, n2, n3), float64, where ``g``
    lives.

    ``q[d][p] = g_d[p] (T_p - T_{p+e_d})`` with ``T = -E.x + theta``, positive along +e_d.
    """
    xp = array_namespace(g, theta)
    load = _check_load(E)
    q = xp.empty(g.shape, dtype=xp.float64, device=device_of(g))
    for d in range(3):
        q[d, ...] = _float64(xp, g[d, ...]) * face_differences(theta, d, voxel_m, load[d])
    return q


def mean_flux(g: Any, theta: Any, voxel_m: float, E: Sequence[float]) -> np.ndarray:
    """Volume-averaged heat flux <q>, W/m^2 (each voxel owns its upper face on every axis).

    Computed where ``g`` and ``theta`` live; the three components come back as a host
    NumPy array of shape (3,).
    """
    xp = array_namespace(g, theta)
    load = _check_load(E)
    n = math.prod(g.shape[1:])
    return np.array([_total(xp, _float64(xp, g[d, ...])
                            * face_differences(theta, d, voxel_m, load[d])) / n
                     for d in range(3)])


def energy_tensor(g: Any, thetas: Sequence[Any], voxel_m: float,
                  directions: tuple[int, ...]) -> np.ndarray:
    """Variational (energy) estimate of the effective tensor block, W/(m K).

    ``K_ij = 1 / (N h) * sum over faces g dT_i dT_j`` with ``dT = T_p - T_q`` of load case
    i and j. It equals the flux average at the exact solution (Hill-Mandel) but its error
    is quadratic in the solver error (the diagonal is an upper bound), so it stays accurate
    where the flux average loses digits, e.g. behind nearly insulating layers.

    Parameters
    ----------
    g : array, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    thetas : sequence of arrays, shape (n1, n2, n3)
        theta of the load cases E = e_i, i in ``directions`` (same namespace as ``g``), K.
    voxel_m : float
        Voxel edge h, m.
    directions : tuple of int
        Load case of every theta.

    Returns
    -------
    ndarray, shape (3, 3)
        Host NumPy, NaN outside the solved block.
    """
    return effective_tensors(g, thetas, voxel_m, directions)[1]


def effective_tensors(g: Any, thetas: Sequence[Any], voxel_m: float,
                      directions: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The flux average and the energy estimate of the effective tensor, W/(m K), in one
    pass over the faces (the temperature drops of every load case are formed once per axis).

    Column j of the flux average is :func:`mean_flux` for E = e_j (``K_ij = <q_i>`` with
    ``E = e_j`` of unit K/m); the energy estimate is :func:`energy_tensor`. Both are
    computed where ``g`` and the thetas live, with float64 sums.

    Parameters
    ----------
    g, thetas, voxel_m, directions
        As in :func:`energy_tensor`.

    Returns
    -------
    flux : ndarray, shape (3, 3)
        Flux average, W/(m K) (host NumPy; NaN in the columns not solved).
    energy : ndarray, shape (3, 3)
        Energy estimate, W/(m K) (host NumPy; NaN outside the solved block).
    """
    if len(thetas) != len(directions):
        raise ValueError(f"directions: {len(directions)} given for {len(thetas)} fields")
    if any(d not in (0, 1, 2) for d in directions):
        raise ValueError(f"directions: expected axes among 0, 1, 2, got {directions!r}")
    xp = array_namespace(g, *thetas)
    n = len(directions)
    flux_sums = np.zeros((3, n))
    energy_sums = np.zeros((n, n))
    for d in range(3):
        gd = _float64(xp, g[d, ...])
        drops = [face_differences(t, d, voxel_m, 1.0 if i == d else 0.0)
                 for t, i in zip(thetas, directions)]
        for a in range(n):
            flux = gd * drops[a]
            flux_sums[d, a] = _total(xp, flux)
            for b in range(a, n):
                energy_sums[a, b] += _total(xp, flux * drops[b])
        del drops
    size = math.prod(g.shape[1:])
    flux = np.full((3, 3), np.nan)
    energy = np.full((3, 3), np.nan)
    for a, i in enumerate(directions):
        flux[:, i] = flux_sums[:, a] / size
        for b, j in enumerate(directions[a:], start=a):
            energy[i, j] = energy[j, i] = energy_sums[a, b] / (size * voxel_m)
    return flux, energy
