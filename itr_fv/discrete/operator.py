"""The discrete operator of :mod:`itr_fv.discrete.model` on a grid of face conductances: load
vectors,
``A theta``, face fluxes, the mean flux and the energy estimate of the effective tensor.

Every function takes the face conductances ``g`` (W/(m^2 K), shape (3, n1, n2, n3),
``g[d][p]`` on the face between voxel p and p + e_d) that an interface law
(:mod:`itr_fv.discrete.interface_law`) produced, so both solvers share them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["cell_centres", "load_vector", "apply_operator", "face_fluxes", "mean_flux",
           "energy_tensor"]


def cell_centres(shape: tuple[int, int, int], voxel_m: float, axis: int) -> np.ndarray:
    """Coordinate (m) of the voxel centres along ``axis``, broadcastable to ``shape``."""
    x = (np.arange(shape[axis]) + 0.5) * voxel_m
    view = [1, 1, 1]
    view[axis] = shape[axis]
    return x.reshape(view)



def load_vector(g: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Right-hand side b(E) of ``A theta = b`` for the macroscopic gradient load E.

    With T = -E.x + theta and the outgoing face flux g (T_p - T_q), conservation in voxel p
    gives ``(A theta)_p = h * sum_d E_d (g_d[p - e_d] - g_d[p])``: a net flux density,
    W/m^2 for E in K/m (every term of the balance is divided by the face area h^2).

    Parameters
    ----------
    g : ndarray, shape (3, n1, n2, n3)
        Face conductances, W/(m^2 K).
    voxel_m : float
        Voxel edge h, m.
    E : array of 3 floats
        Load, K/m (E = e_j gives column j of the effective tensor).

    Returns
    -------
    b : ndarray, shape (n1, n2, n3)
    """
    b = np.zeros(g.shape[1:])
    for d in range(3):
        if E[d] != 0.0:
            b += (voxel_m * E[d]) * (np.roll(g[d], 1, axis=d) - g[d])
    return b


def apply_operator(g: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``A theta``: net outgoing flux of every voxel for the periodic field theta (W/m^2)."""
    out = np.zeros_like(theta)
    for d in range(3):
        up = g[d] * (theta - np.roll(theta, -1, axis=d))
        out += up
        out -= np.roll(up, 1, axis=d)
    return out


def face_fluxes(g: np.ndarray, theta: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Flux density through every face, W/m^2, shape (3, n1, n2, n3).

    ``q[d][p] = g_d[p] (T_p - T_{p+e_d})`` with ``T = -E.x + theta``, positive along +e_d.
    """
    q = np.empty_like(g)
    for d in range(3):
        np.multiply(g[d], theta - np.roll(theta, -1, axis=d) + voxel_m * E[d], out=q[d])
    return q


def mean_flux(g: np.ndarray, theta: np.ndarray, voxel_m: float, E: np.ndarray) -> np.ndarray:
    """Volume-averaged heat flux <q>, W/m^2 (each voxel owns its upper face on every axis)."""
    return np.array([np.mean(g[d] * (theta - np.roll(theta, -1, axis=d) + voxel_m * E[d]))
                     for d in range(3)])


def energy_tensor(g: np.ndarray, thetas: list[np.ndarray], voxel_m: float,
                  directions: tuple[int, ...]) -> np.ndarray:
    """Variational (energy) estimate of the effective tensor block, W/(m K).

    ``K_ij = 1 / (N h) * sum over faces g dT_i dT_j`` with ``dT = T_p - T_q`` of load case
    i and j. It equals the flux average at the exact solution (Hill-Mandel) but its error
    is quadratic in the solver error (the diagonal is an upper bound), so it stays accurate
    where the flux average loses digits, e.g. behind nearly insulating layers.

    Returns
    -------
    ndarray, shape (3, 3)
        NaN outside the solved block.
    """
    K = np.full((3, 3), np.nan)
    N = g[0].size
    for a, i in enumerate(directions):
        for b, j in enumerate(directions[a:], start=a):
            total = 0.0
            for d in range(3):
                dTi = thetas[a] - np.roll(thetas[a], -1, axis=d) + (voxel_m if d == i else 0.0)
                dTj = thetas[b] - np.roll(thetas[b], -1, axis=d) + (voxel_m if d == j else 0.0)
                total += float(np.sum(g[d] * dTi * dTj))
            K[i, j] = K[j, i] = total / (N * voxel_m)
    return K
