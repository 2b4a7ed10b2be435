"""A :class:`~itr_fv.rve.microstructure.Microstructure` from a segmented volume: phases from
the phase table, particles labelled, and what the solve will need checked before any work.

Particles are either given (a second label image, one label per particle) or found:

- **connected components** of each filler phase (``scipy.ndimage.label``) with *face*
  connectivity, the connectivity of the discrete model (heat crosses voxel faces only).
  Joining particles that touch at an edge or a corner as well would change the particle
  count and sizes but not the tensor: two voxels that share no face exchange no heat, and
  two face neighbours of one phase are one particle under either rule; so it is not an
  option. Pieces that meet across the box's periodic boundary are one particle, as the
  solve is periodic (a particle cut by the image's edge would otherwise carry a contact
  resistance at the wrap);
- **watershed split** (``split="watershed"``, scikit-image): where touching particles of
  one phase form one component, the Euclidean distance to the nearest voxel of another
  phase is computed, its local maxima at least ``split_distance_voxels`` apart are the
  particle centres, and a watershed of the negated distance from those markers, inside the
  phase, splits the component along its necks. A larger ``split_distance_voxels`` splits
  less (noisy surfaces give spurious maxima); it should stay below the smallest particle's
  diameter in voxels. The watershed runs on the image as it is; regions that meet across
  the periodic boundary are then joined, as above.

Faces between two different particles carry the contact resistance of their two phases
(the per-area model, ``Materials(contact="area")``: a label image holds no sphere geometry
for the gap model); with connected components these are faces between particles of two
different fillers only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..materials.properties import Materials
from .microstructure import Microstructure, _join_periodic, label_counts, periodic_components
from .phase_table import PhaseTable
from .volume_files import LabelVolume, _label_array

__all__ = ["microstructure_from_image", "label_particles", "periodic_components",
           "watershed_split", "interface_pairs", "image_materials", "particle_sizes_um", "SPLITS",
           "DEFAULT_SPLIT_DISTANCE_VOXELS"]

SPLITS = ("watershed",)
#: Default least distance between two particle centres of the watershed split, voxels.
DEFAULT_SPLIT_DISTANCE_VOXELS = 5


def watershed_split(mask: np.ndarray, *, split_distance_voxels: int =
                    DEFAULT_SPLIT_DISTANCE_VOXELS) -> tuple[np.ndarray, int]:
    """Particles of ``mask`` split at their necks by a watershed of the distance map (see
    the module notes): labels 1..n, int32, and n.

    Raises
    ------
    ValueError
        ``split``: scikit-image is not installed; ``split_distance_voxels``: not an
        integer >= 1.
    """
    if isinstance(split_distance_voxels, bool) or not isinstance(split_distance_voxels,
                                                                 (int, np.integer)) \
            or split_distance_voxels < 1:
        raise ValueError(f"split_distance_voxels: expected an integer >= 1, got "
                         f"{split_distance_voxels!r}")
    try:
        from skimage.feature import peak_local_max
        from skimage.segmentation import watershed
    except ImportError:
        raise ValueError("split: the watershed split needs scikit-image (pip install "
                         "'itr-composites[image]')") from None
    from scipy import ndimage

    distance = ndimage.distance_transform_edt(mask)
    pieces, n = ndimage.label(mask)
    peaks = peak_local_max(distance, min_distance=int(split_distance_voxels), labels=pieces,
                           exclude_border=False)
    markers = np.zeros(mask.shape, dtype=np.int32)
    markers[tuple(peaks.T)] = np.arange(1, len(peaks) + 1)
    # a piece without a maximum of its own (a plateau) keeps one marker at its deepest voxel
    marked = np.zeros(n + 1, dtype=bool)
    marked[pieces[tuple(peaks.T)]] = True
    top = len(peaks)
    for piece in np.flatnonzero(~marked[1:]) + 1:
        where = np.flatnonzero(pieces.ravel() == piece)
        top += 1
        markers.ravel()[where[np.argmax(distance.ravel()[where])]] = top
    regions = watershed(-distance, markers, mask=mask)
    return _join_periodic(regions.astype(np.int32), top)


def label_particles(material_ids: np.ndarray, *, split: str | None = None,
                    split_distance_voxels: int = DEFAULT_SPLIT_DISTANCE_VOXELS) -> np.ndarray:
    """Particle id per voxel (0 = matrix), int32: per filler phase (material id >= 1) its
    periodic face-connected components, or with ``split="watershed"`` its watershed
    regions (module notes); ids run on from one phase to the next."""
    if split is not None and split not in SPLITS:
        raise ValueError(f"split: expected one of {SPLITS} or None, got {split!r}")
    pid = np.zeros(material_ids.shape, dtype=np.int32)
    offset = 0
    for mat in range(1, int(material_ids.max()) + 1):
        mask = material_ids == mat
        if not mask.any():
            continue
        if split is None:
            labels, n = periodic_components(mask)
        else:
            labels, n = watershed_split(mask, split_distance_voxels=split_distance_voxels)
        pid[mask] = labels[mask] + offset
        offset += n
    return pid


def _given_particles(particles: np.ndarray | LabelVolume, material_ids: np.ndarray
                     ) -> np.ndarray:
    """The given particle labels renumbered 1..P, checked against the phases."""
    arr = particles.labels if isinstance(particles, LabelVolume) else particles
    arr = _label_array(arr, "the particle labels", "particles")
    if arr.shape != material_ids.shape:
        raise ValueError(f"particles: shape {arr.shape} differs from the volume's "
                         f"{material_ids.shape}")
    filler = material_ids > 0
    bad = int(np.count_nonzero(filler != (arr > 0)))
    if bad:
        raise ValueError(f"particles: {bad} voxels are matrix in one image and a particle in "
                         "the other; label 0 must be exactly the matrix phase")
    values = np.unique(arr[filler])
    pid = np.zeros(arr.shape, dtype=np.int32)
    pid[filler] = (np.searchsorted(values, arr[filler]) + 1).astype(np.int32)
    return pid


def microstructure_from_image(volume: LabelVolume | np.ndarray, phases: PhaseTable, *,
                              voxel_um: float | None = None,
                              particles: np.ndarray | LabelVolume | None = None,
                              split: str | None = None,
                              split_distance_voxels: int = DEFAULT_SPLIT_DISTANCE_VOXELS
                              ) -> Microstructure:
    """The microstructure of a segmented volume.

    Parameters
    ----------
    volume : LabelVolume or int array (n1, n2, n3)
        The labels (:func:`~itr_fv.rve.volume_files.read_volume`), or an array with
        ``voxel_um``.
    phases : PhaseTable
        Label -> phase; every label of the volume in it, every label of it in the volume.
    voxel_um : float, optional
        Voxel edge, um, for an array (a LabelVolume carries its own).
    particles : int array or LabelVolume, optional
        One label per particle (0 exactly on the matrix), each particle of one phase.
        Default: found per filler phase (module notes).
    split : {"watershed"}, optional
        Split touching particles of one phase (not with ``particles``).
    split_distance_voxels : int
        Least distance between two particle centres of the watershed split, voxels.

    Returns
    -------
    Microstructure
        ``names`` = ``phases.phases`` (the matrix first), no particle table.

    Raises
    ------
    ValueError
        Naming ``volume``, ``phases``, ``particles``, ``split`` or ``voxel_um``.
    """
    if not isinstance(phases, PhaseTable):
        raise ValueError(f"phases: expected a PhaseTable, got {type(phases).__name__}")
    if isinstance(volume, LabelVolume):
        if voxel_um is not None and not math.isclose(voxel_um, volume.voxel_um):
            raise ValueError(f"voxel_um: {voxel_um:g} um differs from the volume's "
                             f"{volume.voxel_um:g} um")
        labels, voxel_um = volume.labels, volume.voxel_um
    else:
        labels = _label_array(volume, "the array", "volume")
        if voxel_um is None:
            raise ValueError("voxel_um: give the voxel edge (um) of a plain array")
    if particles is not None and split is not None:
        raise ValueError("split: the particles are given; a split is for found particles")
    mid = phases.material_ids(labels)
    pid = (label_particles(mid, split=split, split_distance_voxels=split_distance_voxels)
           if particles is None else _given_particles(particles, mid))
    return Microstructure.from_labels(mid, pid, float(voxel_um) * 1e-6, phases.phases)


def interface_pairs(ms: Microstructure) -> dict[tuple[str, str], int]:
    """Faces between two different particles or a particle and the matrix, per sorted pair
    of phase names: what needs an interface resistance (a pair of one filler is a contact
    between two of its particles)."""
    names = ms.names
    m = len(names)
    counts = np.zeros(m * m, dtype=np.int64)
    for d in range(3):
        other_p = np.roll(ms.particle_ids, -1, axis=d)
        other_m = np.roll(ms.material_ids, -1, axis=d)
        cut = ms.particle_ids != other_p
        a, b = ms.material_ids[cut], other_m[cut]
        counts += np.bincount(np.minimum(a, b) * m + np.maximum(a, b), minlength=m * m)
    out = {}
    for code in np.flatnonzero(counts):
        i, j = divmod(int(code), m)
        out[tuple(sorted((names[i], names[j])))] = int(counts[code])
    return out


def particle_sizes_um(ms: Microstructure) -> dict[str, np.ndarray]:
    """Equivalent diameters ``(6 V / pi)^(1/3)`` of the particles, um, per filler phase
    (``V`` the particle's voxels times the voxel volume)."""
    n = ms.n_particles
    if n == 0:
        return {}
    counts = label_counts(ms.particle_ids, n + 1)[1:]
    first = np.zeros(n + 1, dtype=np.int32)
    first[ms.particle_ids.ravel()] = ms.material_ids.ravel()
    h_um = ms.voxel_m * 1e6
    d = (6.0 * counts * h_um ** 3 / math.pi) ** (1.0 / 3.0)
    return {name: d[first[1:] == i] for i, name in enumerate(ms.names) if i > 0
            and np.any(first[1:] == i)}


def image_materials(ms: Microstructure, conductivity: Mapping[str, float],
                    resistance: Mapping[tuple[str, str], float], *,
                    argument: str = "resistance") -> Materials:
    """The :class:`~itr_fv.materials.properties.Materials` of an image solve: the phases'
    conductivities (W/(m K)), the resistances (m^2 K/W) of the pairs the image has faces
    between, and the per-area contact model (a label image has no sphere geometry).

    Raises
    ------
    ValueError
        Naming ``argument`` for the first pair the image needs and ``resistance`` lacks
        (with its face count), or naming ``conductivity`` for a phase without a value.
    """
    matrix = ms.names[0]
    missing = [n for n in ms.names if n not in conductivity]
    if missing:
        raise ValueError(f"conductivity: no conductivity of {', '.join(missing)} (W/(m K))")
    given = {tuple(sorted(p)): float(v) for p, v in resistance.items()}
    needed = interface_pairs(ms)
    lacking = [p for p in needed if p not in given]
    if lacking:
        a, b = lacking[0]
        what = (f"{a}-matrix" if b == matrix else f"{b}-matrix" if a == matrix
                else f"{a}-{b}")
        kind = ("a filler-matrix interface" if matrix in (a, b) else
                "contacts between particles")
        more = f" (and {len(lacking) - 1} more pairs)" if len(lacking) > 1 else ""
        raise ValueError(f"{argument}: the image has {needed[lacking[0]]} faces of {kind} "
                         f"{a}/{b} and no resistance for them{more}; give {what}=VALUE "
                         "(m^2 K/W; 0 for a perfect interface)")
    phases = set(ms.names)
    used = {p: v for p, v in given.items() if set(p) <= phases}
    return Materials({n: float(conductivity[n]) for n in ms.names}, used, matrix=matrix,
                     contact="area")
