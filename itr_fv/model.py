"""The discrete model: face conductances with interface resistance, load vectors, fluxes.

Both solvers (``itr_fv.homogenize`` and ``itr_fft.homogenize``) solve exactly the system
defined here. Cell-centred finite volumes on an n1 x n2 x n3 periodic grid of cubic voxels
of edge h. The face between voxel p and its neighbour q = p + e_d carries the conductance
per unit area (W/(m^2 K))::

    g = 1 / (h / (2 k_p) + R_pq * s_pq + h / (2 k_q))

with R_pq = 0 inside one particle or inside the matrix, R_pq = R(material_p, material_q)
at a particle-matrix face and at a face between two different particles, and s_pq the
staircase factor |n_x| + |n_y| + |n_z| of the true surface normal n.

Layout convention: ``g[d][i, j, k]`` is the face between voxel (i, j, k) and its periodic
neighbour (i, j, k) + e_d. With the periodic split T = -E.x + theta, conservation in
every voxel reads ``A theta = b(E)`` (see :func:`apply_operator`, :func:`load_vector`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage
import scipy.sparse
import scipy.sparse.csgraph

from .materials import Materials
from .microstructure import Microstructure

__all__ = [
    "FaceGeometry", "face_geometry", "face_conductances", "load_vector", "apply_operator",
    "face_fluxes", "mean_flux", "energy_tensor", "connected_components", "cell_centres",
]


@dataclass(frozen=True)
class FaceGeometry:
    """Interface faces of a microstructure, independent of material values.

    A parameter change (conductivities, resistances) only needs :meth:`conductances`
    again; the geometry is computed once.

    Attributes
    ----------
    shape : tuple of int
        Grid shape (n1, n2, n3).
    voxel_m : float
        Voxel edge h, m.
    material_ids : ndarray of int32
        Material id per voxel (shared with the microstructure, not copied).
    index : tuple of 3 int64 arrays
        Flat index of the lower voxel p of every interface face, per axis.
    mat_lo, mat_hi : tuple of 3 int32 arrays
        Material ids of p and of q = p + e_d at those faces.
    s : tuple of 3 float64 arrays
        Staircase factor of those faces (1 when the correction is off).
    staircase : str
        How s was obtained: ``"off"``, ``"spheres"`` (analytic normals) or ``"image"``.
    """

    shape: tuple[int, int, int]
    voxel_m: float
    names: tuple[str, ...]
    material_ids: np.ndarray
    index: tuple[np.ndarray, np.ndarray, np.ndarray]
    mat_lo: tuple[np.ndarray, np.ndarray, np.ndarray]
    mat_hi: tuple[np.ndarray, np.ndarray, np.ndarray]
    contact: tuple[np.ndarray, np.ndarray, np.ndarray]
    s: tuple[np.ndarray, np.ndarray, np.ndarray]
    staircase: str

    @property
    def n_interface_faces(self) -> int:
        return int(sum(a.size for a in self.index))

    def conductances(self, materials: Materials) -> np.ndarray:
        """Face conductances per unit area, W/(m^2 K).

        Parameters
        ----------
        materials : Materials
            Conductivities and resistances; every phase of the microstructure and every
            interface pair it holds must be present.

        Returns
        -------
        g : ndarray, shape (3, n1, n2, n3)
            ``g[d][p]`` is the conductance of the face between p and p + e_d.
        """
        if not isinstance(materials, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(materials).__name__}")
        k, R = materials.tables(self.names)
        h = self.voxel_m
        half_r = (0.5 * h) / k  # h / (2 k) per material id, m^2 K / W
        rc = half_r[self.material_ids]
        g = np.empty((3,) + self.shape, dtype=np.float64)
        for d in range(3):
            np.add(rc, np.roll(rc, -1, axis=d), out=g[d])
            np.divide(1.0, g[d], out=g[d])
            idx = self.index[d]
            if idx.size == 0:
                continue
            lo, hi = self.mat_lo[d], self.mat_hi[d]
            r_face = R[lo, hi]
            if np.isnan(r_face).any():
                j = int(np.flatnonzero(np.isnan(r_face))[0])
                materials.resistance_between(self.names[lo[j]], self.names[hi[j]])  # raises
            with np.errstate(invalid="ignore"):
                series = half_r[lo] + half_r[hi] + np.where(np.isinf(r_face), np.inf,
                                                            r_face * self.s[d])
            g[d].reshape(-1)[idx] = 1.0 / series
        return g


def cell_centres(shape: tuple[int, int, int], voxel_m: float, axis: int) -> np.ndarray:
    """Coordinate (m) of the voxel centres along ``axis``, broadcastable to ``shape``."""
    x = (np.arange(shape[axis]) + 0.5) * voxel_m
    view = [1, 1, 1]
    view[axis] = shape[axis]
    return x.reshape(view)


def _min_image(dx: np.ndarray, box: np.ndarray) -> np.ndarray:
    return dx - box * np.round(dx / box)


def _staircase_factor(n: np.ndarray) -> np.ndarray:
    """s = |n_x| + |n_y| + |n_z| for unnormalised normals n (shape (m, 3)); 1 where n = 0."""
    norm = np.sqrt((n * n).sum(axis=1))
    s = np.ones(n.shape[0])
    ok = norm > 0
    s[ok] = np.abs(n[ok]).sum(axis=1) / norm[ok]
    return s


def _self_image_faces(table, pid: np.ndarray, pq: np.ndarray, d: int,
                      shape: tuple[int, int, int], h: float) -> np.ndarray:
    """Flat indices of axis-d faces where a sphere meets its own periodic image.

    Both voxels carry the same particle id, but they lie in different periodic images of
    the sphere (their minimum-image offsets from its centre differ by the box length, not
    by h). Only spheres whose diameter comes within two voxels of the box edge can do this.
    """
    L = shape[d] * h
    big = np.flatnonzero(2.0 * table.radii_m > L - 2.0 * h) + 1
    if big.size == 0:
        return np.zeros(0, dtype=np.int64)
    cand = np.flatnonzero((np.isin(pid, big) & (pid == pq)).ravel())
    if cand.size == 0:
        return cand
    i_d = np.unravel_index(cand, shape)[d]
    c = table.centers_m[pid.ravel()[cand] - 1, d]
    u_p = _min_image((i_d + 0.5) * h - c, np.array(L))
    u_q = _min_image((i_d + 1.5) * h - c, np.array(L))
    return cand[np.abs(u_q - u_p - h) > 0.5 * h]


def face_geometry(ms: Microstructure, staircase: bool = True,
                  image_smoothing: float = 1.5) -> FaceGeometry:
    """Find the interface faces of ``ms`` and their staircase factors.

    Parameters
    ----------
    ms : Microstructure
        The voxel image.
    staircase : bool
        Apply the staircase correction s = |n_x| + |n_y| + |n_z|. With a particle table,
        n is analytic: from the particle centre to the face centre at a particle-matrix
        face, along the (minimum-image) line of centres at a particle-particle face. For
        a plain label image (no table) n is estimated from the gradient of the solid
        indicator smoothed by a periodic Gaussian of ``image_smoothing`` voxels at
        particle-matrix faces, and s = 1 is kept at particle-particle faces. With a
        particle table, a sphere that meets its own periodic image (diameter within two
        voxels of the box) gets contact resistance there too, with s = 1; a plain label
        image cannot tell this apart from the inside of the particle.
    image_smoothing : float
        Gaussian width (voxels) of the image-based normal estimate.

    Returns
    -------
    FaceGeometry
    """
    if not isinstance(ms, Microstructure):
        raise ValueError(f"ms: expected a Microstructure, got {type(ms).__name__}")
    shape, h = ms.shape, ms.voxel_m
    pid, mid = ms.particle_ids, ms.material_ids
    box = np.array(shape, dtype=np.float64) * h
    index, lo, hi, contact, s_all = [], [], [], [], []
    table = ms.particles
    mode = "off" if not staircase else ("spheres" if table is not None else "image")
    grad = None
    if mode == "image" and ms.n_particles:
        solid = scipy.ndimage.gaussian_filter((pid > 0).astype(np.float64), image_smoothing,
                                              mode="wrap")
        grad = [0.5 * (np.roll(solid, -1, axis=a) - np.roll(solid, 1, axis=a)) for a in range(3)]
    for d in range(3):
        pq = np.roll(pid, -1, axis=d)
        idx = np.flatnonzero((pid != pq).ravel())
        if table is not None:
            idx = np.union1d(idx, _self_image_faces(table, pid, pq, d, shape, h))
        p_lo = pid.ravel()[idx]
        p_hi = pq.ravel()[idx]
        index.append(idx)
        lo.append(mid.ravel()[idx])
        hi.append(np.roll(mid, -1, axis=d).ravel()[idx])
        is_contact = (p_lo > 0) & (p_hi > 0)
        contact.append(is_contact)
        s = np.ones(idx.size)
        # a sphere touching its own periodic image: the line of centres is e_d, s = 1
        self_image = is_contact & (p_lo == p_hi)
        if mode == "spheres" and idx.size:
            ijk = np.stack(np.unravel_index(idx, shape), axis=1).astype(np.float64)
            x_face = (ijk + 0.5) * h
            x_face[:, d] += 0.5 * h
            pm = ~is_contact
            part = np.maximum(p_lo, p_hi)[pm] - 1
            n_pm = _min_image(x_face[pm] - table.centers_m[part], box)
            s[pm] = _staircase_factor(n_pm)
            pp = is_contact & ~self_image
            if pp.any():
                a = p_lo[pp] - 1
                b = p_hi[pp] - 1
                n_pp = _min_image(table.centers_m[b] - table.centers_m[a], box)
                s[pp] = _staircase_factor(n_pp)
        elif mode == "image" and idx.size:
            pm = np.flatnonzero(~is_contact)
            p_flat = idx[pm]
            q_flat = np.ravel_multi_index(
                tuple(np.mod(c + (1 if a == d else 0), shape[a])
                      for a, c in enumerate(np.unravel_index(p_flat, shape))), shape)
            n_est = np.stack([0.5 * (grad[a].ravel()[p_flat] + grad[a].ravel()[q_flat])
                              for a in range(3)], axis=1)
            s[pm] = _staircase_factor(n_est)
        s_all.append(s)
    return FaceGeometry(tuple(shape), float(h), tuple(ms.names), mid, tuple(index), tuple(lo),
                        tuple(hi), tuple(contact), tuple(s_all), mode)


def face_conductances(ms: Microstructure, mat: Materials, staircase: bool = True) -> np.ndarray:
    """Face conductances per unit area g, W/(m^2 K), shape (3, n1, n2, n3).

    Shorthand for ``face_geometry(ms, staircase).conductances(mat)``.
    """
    return face_geometry(ms, staircase).conductances(mat)


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


def connected_components(g: np.ndarray) -> tuple[int, np.ndarray]:
    """Connected components of the voxel graph whose edges are faces with g > 0.

    Returns
    -------
    n : int
        Number of components (1 unless insulating interfaces cut off clusters).
    labels : ndarray of int32, shape (n1, n2, n3)
        Component of every voxel; component 0 is the largest.
    """
    shape = g.shape[1:]
    N = int(np.prod(shape))
    ids = np.arange(N).reshape(shape)
    rows, cols = [], []
    for d in range(3):
        mask = g[d] > 0
        rows.append(ids[mask])
        cols.append(np.roll(ids, -1, axis=d)[mask])
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    adj = scipy.sparse.coo_array((np.ones(r.size, dtype=np.int8), (r, c)), shape=(N, N)).tocsr()
    n, labels = scipy.sparse.csgraph.connected_components(adj, directed=False)
    if n > 1:
        sizes = np.bincount(labels, minlength=n)
        order = np.argsort(-sizes, kind="stable")
        remap = np.empty(n, dtype=np.int64)
        remap[order] = np.arange(n)
        labels = remap[labels]
    return int(n), labels.reshape(shape).astype(np.int32)
