"""A flat resistive interface at an angle to the grid: what limits the order of the laws.

A periodic laminate of two phases (filler k_a, matrix k_m = 1 W/(m K)) whose interfaces are
the planes ``p x + q y + r z = (j + {0, 1/2}) L`` (two interfaces per period, resistance R
each) has the exact effective tensor ``K = k_par (I - n n) + k_perp n n`` with
``k_par = (k_a + k_m) / 2`` and ``1 / k_perp = (1/k_a + 1/k_m) / 2 + 2 R / P`` (P the period
along the unit normal n). It has no curvature and no contacts, so whatever error a law has
here is the error of representing a tilted resistive interface by one conductance per face
of a 7-point stencil. Both laws of ``itr_fv.discrete.interface_law`` are applied to it unchanged:
the
staircase law to the label image with the staircase factor of n, the segment law to the
segment geometry of the planes (lengths in each phase and one crossing per plane crossed,
with either share). Solved with itr_fft (tol 1e-10, three load cases). Writes
``validation/results/tilted_interface.md``.

Usage::

    python validation/tilted_interface_study.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from itr_fv import Materials, Microstructure, homogenize  # noqa: E402
from itr_fv.discrete.cut_cells import SHARES, SurfaceCuts  # noqa: E402
from itr_fv.discrete.face_geometry import FaceGeometry  # noqa: E402
from itr_fv.discrete.interface_law import SegmentLaw, StaircaseLaw  # noqa: E402
from itr_fv.discrete.problem import DiscreteProblem  # noqa: E402
from itr_fv.rve.sphere_geometry import staircase_factor  # noqa: E402

OUT = ROOT / "validation" / "results" / "tilted_interface.md"
L = 1e-5
K_M = 1.0
NORMALS = ((1, 0, 0), (1, 1, 0), (1, 2, 0), (1, 1, 1))
GRIDS = (16, 32, 64, 128)
#: (k_a / k_m, R k_m / P): resistive interfaces without and with a bulk contrast
CASES = ((1.0, 0.2), (10.0, 0.2), (10.0, 1.0), (170.0, 0.0))


#: The planes sit at u = (j + {0, 1/2}) L + OFFSET: off the voxel centres and faces of every grid.
OFFSET = 0.0123 * L


def phase_value(u: np.ndarray) -> np.ndarray:
    """Filler where ``(u - OFFSET) / L mod 1 < 1/2`` (u = p x + q y + r z)."""
    return np.mod((u - OFFSET) / L, 1.0) < 0.5


def filler_measure(u: np.ndarray) -> np.ndarray:
    """``int_0^u 1[filler](v) dv``: the filler's share of u, exact."""
    v = u - OFFSET
    whole = np.floor(v / L)
    return whole * 0.5 * L + np.minimum(v - whole * L, 0.5 * L)


def laminate_geometry(n: int, pqr: tuple[int, int, int], law
                      ) -> tuple[FaceGeometry, Microstructure]:
    """Face geometry of the laminate on an n^3 grid for ``law`` (staircase or segment)."""
    h = L / n
    c = (np.arange(n) + 0.5) * h
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    normal = np.array(pqr, dtype=float)
    u = pqr[0] * X + pqr[1] * Y + pqr[2] * Z
    filler = phase_value(u)
    mid = filler.astype(np.int32)
    ms = Microstructure(mid, mid.copy(), h, ["matrix", "filler"])
    s_value = float(staircase_factor(normal[None, :])[0])
    index, lo, hi, contact, s, cut_index, lengths, shares = [], [], [], [], [], [], [], []
    for d in range(3):
        q = np.roll(mid, -1, axis=d)
        idx = np.flatnonzero((mid != q).ravel())
        index.append(idx)
        lo.append(mid.ravel()[idx])
        hi.append(q.ravel()[idx])
        contact.append(np.zeros(idx.size, dtype=bool))
        s.append(np.full(idx.size, s_value))
        # along the segment x_p -> x_p + h e_d, u runs from u0 to u0 + pqr[d] h: it crosses a
        # plane at every multiple of L / 2
        u0 = u.ravel()
        du = pqr[d] * h
        k0 = np.floor(2 * (u0 - OFFSET) / L)
        k1 = np.floor(2 * (u0 + du - OFFSET) / L)
        crossings = np.abs(k1 - k0)
        cut = np.flatnonzero(crossings > 0)
        # length in the filler: u is linear along the segment
        inside = h * (filler_measure(u0[cut] + du) - filler_measure(u0[cut])) / du
        w = SHARES[law.share](np.tile(normal / np.linalg.norm(normal), (cut.size, 1)), d) \
            if isinstance(law, SegmentLaw) else np.zeros(cut.size)
        cut_index.append(cut)
        lengths.append(np.column_stack([np.zeros(cut.size), inside]))
        shares.append(np.column_stack([np.zeros(cut.size), crossings[cut] * w]))
    cuts = (SurfaceCuts(tuple(cut_index), tuple(lengths), tuple(shares), law.share)
            if isinstance(law, SegmentLaw) else None)
    geom = FaceGeometry((n, n, n), h, ("matrix", "filler"), mid, tuple(index), tuple(lo),
                        tuple(hi), tuple(contact), tuple(s), "spheres", contact_model="gap",
                        law=law, cuts=cuts, particle_mat=np.array([0, 1]))
    return geom, ms


def exact(pqr, k_ratio: float, r_over_p: float) -> np.ndarray:
    n = np.array(pqr, dtype=float)
    n /= np.linalg.norm(n)
    k_par = 0.5 * (k_ratio + 1.0) * K_M
    k_perp = 1.0 / (0.5 * (1.0 / (k_ratio * K_M) + 1.0 / K_M) + 2 * r_over_p / K_M)
    return k_par * (np.eye(3) - np.outer(n, n)) + k_perp * np.outer(n, n)


def main() -> None:
    laws = {"staircase": StaircaseLaw("gap"), "segment": SegmentLaw("staircase"),
            "segment-normal": SegmentLaw("normal")}
    lines = ["# A flat resistive interface at an angle to the grid (issue 28)", "",
             " ".join(__doc__.split("\n\n")[1].split()), "",
             "Error = max over the diagonal of |K_ii / K_ii,exact - 1| (%), and the observed "
             "order p of that error over the three finest grids.", "",
             "| normal (p, q, r) | k_a/k_m | R k_m / P | law | "
             + " | ".join(f"n = {n}" for n in GRIDS) + " | p |",
             "|---" * (5 + len(GRIDS)) + "|"]
    t0 = time.perf_counter()
    for pqr in NORMALS:
        for k_ratio, r_over_p in CASES:
            ref = exact(pqr, k_ratio, r_over_p)
            P = L / np.linalg.norm(pqr)
            mat = Materials({"matrix": K_M, "filler": k_ratio * K_M},
                            {("filler", "matrix"): r_over_p * P / K_M}, "matrix", contact="gap")
            for name, law in laws.items():
                errs = []
                for n in GRIDS:
                    geom, ms = laminate_geometry(n, pqr, law)
                    problem = DiscreteProblem(ms, contact="gap", geometry=geom,
                                              interface=law)
                    K = homogenize(problem, mat, solver="fft", tol=1e-10, store_fields=False).k_eff
                    errs.append(float(np.max(np.abs(np.diag(K) / np.diag(ref) - 1))))
                tail = np.array(errs[-3:])
                p = (-np.polyfit(np.log(GRIDS[-3:]), np.log(tail), 1)[0]
                     if np.all(tail > 1e-9) else float("nan"))
                lines.append(f"| {pqr} | {k_ratio:g} | {r_over_p:g} | {name} | "
                             + " | ".join(f"{100 * e:.3f}" for e in errs) + f" | {p:.2f} |")
                print(lines[-1], flush=True)
    lines += ["", f"Solve time {time.perf_counter() - t0:.0f} s on the shared 2-core machine.",
              "", FINDINGS]
    OUT.write_text("\n".join(lines) + "\n")
    print(f"wrote {OUT}")


FINDINGS = """## Findings

- Along a grid axis ((1, 0, 0)) every law is exact at every grid: lengths, the staircase
  factor (1) and the shares (1) are all right there.
- Tilted, every law converges at first order (p = 0.85 ... 1.02), with the same error to
  three digits under all three laws wherever the normal makes equal angles with the cut axes
  ((1, 1, 0), (1, 1, 1)), and with errors of 1-2 % at n = 128 (45 voxels between
  interfaces at (1, 1, 0)). The error is there with equal conductivities and a resistance
  only (k_a = k_m), and with a conductivity contrast and no resistance (k_a/k_m = 170,
  R = 0): it is not the share rule of R, nor the bulk lengths. A face cut by a tilted
  interface carries one conductance for two fluxes that need different ones: the flux
  normal to the interface crosses it in series (harmonic mean, with R), the flux along it
  does not cross it at all (arithmetic mean, no R). A 7-point stencil with one conductance
  per face cannot give both, so the flux along the interface is throttled in a layer one
  voxel thick: a first-order error of the effective tensor for any law of this form.
- Second order needs the cross terms of the cut cells: a full conductivity tensor per cut
  cell (laminate composite voxels) with a stencil that couples the axes (19 or 27 points),
  or an immersed-interface stencil. Both change the operator that both solvers, the
  multigrid and the reduced basis share."""


if __name__ == "__main__":
    main()
