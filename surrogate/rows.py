"""The row formats shared by the Parquet stores: a tensor as columns, an RVE's identity."""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["tensor_columns", "tensor_of", "rve_id"]


def tensor_columns(k: np.ndarray) -> dict[str, float]:
    """The 3x3 tensor (W/(m K)) as the row columns ``k_xx`` ... ``k_zz`` and ``k_iso``."""
    row = {f"k_{ax}{bx}": float(k[a, b]) for a, ax in enumerate("xyz")
           for b, bx in enumerate("xyz")}
    row["k_iso"] = float(np.trace(k) / 3.0)
    return row


def tensor_of(row: dict) -> np.ndarray:
    """The 3x3 tensor of a row written with :func:`tensor_columns`."""
    return np.array([[row[f"k_{a}{b}"] for b in "xyz"] for a in "xyz"])


def rve_id(centers_m: np.ndarray, radii_m: np.ndarray, materials: list[str],
           shape: tuple[int, int, int], voxel_m: float, contact=None) -> str:
    """Hash of a particle table, its voxel grid and its contact film (a
    :class:`~itr_fv.rve.contact_film.ContactFilm`, None: the default), 16 hex digits: the
    RVE's identity."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(centers_m, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(radii_m, dtype="<f8").tobytes())
    h.update("\0".join(materials).encode())
    h.update(np.asarray(shape, dtype="<i8").tobytes())
    h.update(np.float64(voxel_m).astype("<f8").tobytes())
    if contact is not None:
        h.update(np.asarray(contact.args, dtype="<f8").tobytes())
    return h.hexdigest()[:16]
