"""The discrete problem of one RVE: geometry and contact model once, values per parameter set.

A :class:`DiscreteProblem` holds what does not change when conductivities and resistances
change: the microstructure, its interface faces with their staircase factors, contact pairs
and film thicknesses (:class:`~itr_fv.discrete.model.FaceGeometry`) and the contact model. For every
parameter set :meth:`DiscreteProblem.system` gives the face conductances and the clusters
that insulating interfaces cut off. Both solvers take a problem in place of a
microstructure, so a campaign builds it once per RVE::

    problem = DiscreteProblem(ms, contact="gap")
    for mat in parameter_sets:
        res = itr_fv.homogenize(problem, mat, solver="fft")

The conductances come from the geometry's class arrays
(:mod:`itr_fv.discrete.face_classes`) by one elementwise pass in any array API namespace:
``problem.system(mat, xp=xp, device=device)`` gives them where a backend's arrays live
(the class arrays move there once per problem and namespace/device); NumPy on the host
is the default.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import PhysicalScaleWarning, VoxelContactWarning
from ..materials.properties import CONTACT_MODELS, Materials
from ..rve.microstructure import Microstructure
from .connectivity import FloatingClusters
from .face_classes import FaceClasses, to_host
from .interface_law import InterfaceLaw
from .model import DEFAULT_TOUCH_GAP_M, FaceGeometry, connected_components, face_geometry

__all__ = ["DiscreteProblem", "DiscreteSystem", "floating_clusters", "IMPLAUSIBLE_VOXEL_M"]

#: Voxels above this edge (m) with a finite interface resistance warn: this package's domain
#: is particle-filled composites with micrometre fillers, and a resistance in m^2 K/W
#: only means something against voxels in metres.
IMPLAUSIBLE_VOXEL_M = 1e-3


@dataclass(frozen=True)
class DiscreteSystem:
    """The values of the discrete system for one parameter set.

    Attributes
    ----------
    g : array, shape (3, n1, n2, n3)
        Face conductances per unit area, W/(m^2 K): a NumPy ndarray, or an array of the
        namespace and device :meth:`DiscreteProblem.system` was asked for.
    floating : FloatingClusters
        Clusters cut off by insulating faces.
    labels : ndarray of int32 or None
        Connected component of every voxel (None when the grid is connected).
    particle_ids : ndarray of int32 or None
        Particle of every voxel, 0 = matrix (the microstructure's own array, not a copy):
        the groups whose constants are the slow modes of a resistive-interface system,
        which a preconditioner may deflate. None when unknown.
    """

    g: Any
    floating: FloatingClusters
    labels: np.ndarray | None
    particle_ids: np.ndarray | None = None


def floating_clusters(g: np.ndarray) -> tuple[FloatingClusters, np.ndarray | None]:
    """Clusters cut off by insulating faces; returns the summary and the labels (or None)."""
    if np.all(g > 0):
        return FloatingClusters(0, np.zeros(0, dtype=np.int64), 0.0), None
    n, labels = connected_components(g)
    if n == 1:
        return FloatingClusters(0, np.zeros(0, dtype=np.int64), 0.0), None
    sizes = np.bincount(labels.ravel(), minlength=n)
    return FloatingClusters(n - 1, sizes[1:], float(sizes[1:].sum() / labels.size)), labels


def _floating_clusters_in(xp: Any, g: Any) -> tuple[FloatingClusters, np.ndarray | None]:
    """:func:`floating_clusters` of conductances of the namespace ``xp``: the check for
    insulating faces runs where ``g`` lives; only a grid that has some comes to the host."""
    if bool(xp.all(g > 0)):
        return FloatingClusters(0, np.zeros(0, dtype=np.int64), 0.0), None
    return floating_clusters(to_host(g))


class DiscreteProblem:
    """Geometry and contact model of one RVE, reused for any number of parameter sets.

    Parameters
    ----------
    ms : Microstructure
        The voxel image (with its particle table for ``contact="gap"``).
    contact : {"area", "gap"}
        Contact model; the materials given to :meth:`system` must use the same.
    staircase : bool
        Staircase correction of the interface resistances.
    touch_gap_m : float
        Pairs closer than this (m) touch and carry contact spots (``contact="gap"``).
    geometry : FaceGeometry, optional
        A precomputed geometry of ``ms`` for this contact model.
    interface : {"staircase", "segment"} or InterfaceLaw
        The interface law (:mod:`itr_fv.discrete.interface_law`): ``"staircase"`` (centre labels,
        half voxels, staircase factor) or ``"segment"`` (cut cells: lengths and crossings
        along every face's segment through the analytic spheres; gap contacts only).
    """

    def __init__(self, ms: Microstructure, *, contact: str = "gap", staircase: bool = True,
                 touch_gap_m: float = DEFAULT_TOUCH_GAP_M,
                 geometry: FaceGeometry | None = None,
                 interface: str | InterfaceLaw = "staircase") -> None:
        if not isinstance(ms, Microstructure):
            raise ValueError(f"ms: expected a Microstructure, got {type(ms).__name__}")
        if contact not in CONTACT_MODELS:
            raise ValueError(f"contact: expected one of {CONTACT_MODELS}, got {contact!r}")
        if geometry is None:
            geometry = face_geometry(ms, staircase, contact=contact, touch_gap_m=touch_gap_m,
                                     interface=interface)
        elif not isinstance(geometry, FaceGeometry) or geometry.shape != ms.shape:
            raise ValueError("geometry: expected the FaceGeometry of this microstructure")
        elif geometry.contact_model != contact:
            raise ValueError(f"geometry: built for contact={geometry.contact_model!r}, not "
                             f"{contact!r}")
        elif geometry.law.name != getattr(interface, "name", interface):
            raise ValueError(f"geometry: built for interface={geometry.law.name!r}, not "
                             f"{interface!r}")
        self.microstructure = ms
        self.geometry = geometry
        self.contact = contact
        self._classes: dict[tuple[str, str], FaceClasses] = {}

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["_classes"] = {}  # device arrays stay where they are
        return state

    @classmethod
    def for_materials(cls, ms: Microstructure, mat: Materials, staircase: bool = True,
                      geometry: FaceGeometry | None = None) -> "DiscreteProblem":
        """The problem of ``ms`` under the contact model of ``mat``."""
        if not isinstance(mat, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(mat).__name__}")
        if geometry is not None and isinstance(geometry, FaceGeometry) \
                and geometry.contact_model != mat.contact:
            raise ValueError(f"geometry: built for contact={geometry.contact_model!r}, but the "
                             f"materials use contact={mat.contact!r}")
        interface = geometry.law if isinstance(geometry, FaceGeometry) else "staircase"
        return cls(ms, contact=mat.contact, staircase=staircase, geometry=geometry,
                   interface=interface)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.microstructure.shape

    @property
    def voxel_m(self) -> float:
        return self.microstructure.voxel_m

    def face_classes(self, *, xp: Any = None, device: Any = None) -> FaceClasses:
        """The geometry's class arrays in the namespace ``xp`` on ``device``, moved there
        once per problem and (namespace, device); the host NumPy ones by default."""
        host = self.geometry.face_classes()
        if xp is None:
            if device not in (None, "cpu"):
                raise ValueError(f"device: {device!r} needs its array namespace xp")
            return host
        key = (getattr(xp, "__name__", repr(xp)), repr(device))
        cache = self.__dict__.setdefault("_classes", {})
        classes = cache.get(key)
        if classes is None:
            classes = cache[key] = host.to(xp, device)
        return classes

    def conductances(self, mat: Materials, *, xp: Any = None, device: Any = None) -> Any:
        """Face conductances per unit area of the parameter set ``mat``, W/(m^2 K), shape
        (3, n1, n2, n3), as an array of ``xp`` on ``device`` (default NumPy on the host)."""
        if not isinstance(mat, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(mat).__name__}")
        return self.geometry.conductances(mat, classes=self.face_classes(xp=xp, device=device))

    def system(self, mat: Materials, *, xp: Any = None, device: Any = None) -> DiscreteSystem:
        """Face conductances and floating clusters for the parameter set ``mat``.

        Warns (:class:`~itr_fv.checks.PhysicalScaleWarning`) for voxels above 1 mm with a
        finite interface resistance, and (:class:`~itr_fv.checks.VoxelContactWarning`) when
        the per-area contact model acts on contact faces.

        Parameters
        ----------
        mat : Materials
            The parameter set, under the problem's contact model.
        xp : namespace, optional
            Array API namespace of the conductances (``array_api_strict``,
            ``array_api_compat.cupy``, ...; default NumPy).
        device : object, optional
            Device of ``xp`` for them (default: the namespace's default device).

        Returns
        -------
        DiscreteSystem
            ``g`` in ``xp`` on ``device``; the cluster labels (if any) on the host.
        """
        if not isinstance(mat, Materials):
            raise ValueError(f"mat: expected a Materials object, got {type(mat).__name__}")
        if mat.contact != self.contact:
            raise ValueError(f"mat: uses contact={mat.contact!r}, but the problem was built "
                             f"for contact={self.contact!r}")
        self._warn_scale(mat)
        if self.contact == "area" and self.geometry.n_contact_faces:
            warnings.warn(
                f"contact: the per-area contact resistance (contact='area') acts on "
                f"{self.geometry.n_contact_faces} voxel faces between particles whose total "
                f"area scales with the voxel ({self.voxel_m * 1e6:.4g} um here): its value "
                "belongs to the voxel size it was identified at. contact='gap' converges "
                "under refinement.", VoxelContactWarning, stacklevel=4)
        classes = self.face_classes(xp=xp, device=device)
        g = self.geometry.conductances(mat, classes=classes)
        floating, labels = (floating_clusters(g) if classes.scatter
                            else _floating_clusters_in(classes.xp, g))
        return DiscreteSystem(g, floating, labels, self.microstructure.particle_ids)

    def _warn_scale(self, mat: Materials) -> None:
        h = self.voxel_m
        if h <= IMPLAUSIBLE_VOXEL_M:
            return
        finite = [v for v in mat.resistance.values() if 0.0 < v < math.inf]
        if finite:
            warnings.warn(
                f"voxel_m: the voxel edge is {h:.4g} m (> 1 mm) while interface resistances "
                f"are finite (up to {max(finite):.3g} m^2 K/W). Lengths are in metres: if "
                f"{h:.4g} was meant in micrometres, the voxel is voxel_m={h * 1e-6:.4g}. Taken "
                "as metres, the interfaces weigh ~1e6 times too little and k_eff comes out too "
                "high.", PhysicalScaleWarning, stacklevel=5)

    def __repr__(self) -> str:
        return (f"DiscreteProblem({self.microstructure!r}, contact={self.contact!r}, "
                f"interface={self.geometry.law.name!r}, "
                f"{self.geometry.n_interface_faces} interface faces, "
                f"{self.geometry.n_contact_faces} contact faces)")
