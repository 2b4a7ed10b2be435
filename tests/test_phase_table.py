"""Labels to phases and particles (itr_fv.rve.phase_table, itr_fv.rve.from_image): the
table maps and refuses, connected components find separate spheres (across the periodic
boundary too), the watershed splits two touching spheres, given particle labels are used
as given, and the image's resistance table is checked against the faces it has."""

import math

import numpy as np
import pytest

from itr_fv import PhaseTable, microstructure_from_image
from itr_fv.rve.from_image import (
    image_materials,
    interface_pairs,
    label_particles,
    particle_sizes_um,
)
from tests.refusals import refuses


def balls(n: int, centres, radius: float, labels=None) -> np.ndarray:
    """Label image of periodic balls (voxel centres at i + 1/2, in voxels): ``labels[i]``
    (default 1) inside ball ``i``, 0 elsewhere."""
    g = np.indices((n, n, n)) + 0.5
    out = np.zeros((n, n, n), dtype=np.uint8)
    for i, c in enumerate(centres):
        d = g - np.reshape(c, (3, 1, 1, 1))
        d -= n * np.round(d / n)
        out[(d * d).sum(axis=0) <= radius ** 2] = 1 if labels is None else labels[i]
    return out


TABLE = PhaseTable.of({0: "matrix", 1: "Al2O3", 2: "AlN"}, "silicone")


def test_table_from_items_file_and_mapping(tmp_path):
    parsed = PhaseTable.parse(["0=matrix", "1=Al2O3", "2=AlN"], "silicone")
    (tmp_path / "p.toml").write_text('[phases]\n0 = "silicone"\n1 = "Al2O3"\n2 = "AlN"\n')
    assert parsed == TABLE == PhaseTable.read(tmp_path / "p.toml", "silicone")
    assert TABLE.phases == ("silicone", "Al2O3", "AlN")
    lab = np.array([[[0, 1, 2, 2]]], dtype=np.uint16)
    assert TABLE.material_ids(lab).tolist() == [[[0, 1, 2, 2]]]
    # two labels may name one phase
    two = PhaseTable.of({0: "matrix", 5: "Al2O3", 9: "Al2O3"}, "silicone")
    assert two.material_ids(np.array([[[9, 0, 5]]])).tolist() == [[[1, 0, 1]]]


def test_table_refusals(tmp_path):
    with refuses(ValueError, "phases"):
        PhaseTable.parse(["0=matrix", "1"], "silicone")
    with refuses(ValueError, "phases"):
        PhaseTable.parse(["-1=Al2O3", "0=matrix"], "silicone")
    with refuses(ValueError, "phases"):
        PhaseTable.parse(["1=Al2O3"], "silicone")            # no matrix
    with refuses(ValueError, "phases"):
        PhaseTable.parse(["0=matrix", "0=Al2O3"], "silicone")
    with refuses(ValueError, "phases"):
        TABLE.check_phases(("silicone", "Al2O3"))            # AlN not in the system
    lab = np.array([[[0, 1, 3]]], dtype=np.uint8)
    with refuses(ValueError, "volume") as info:
        TABLE.material_ids(lab)                              # 3 not in the table
    assert "label 3" in str(info.value)
    with refuses(ValueError, "phases") as info:
        TABLE.material_ids(np.array([[[0, 1, 1]]]))          # 2 (AlN) holds no voxel
    assert "label 2" in str(info.value)
    (tmp_path / "bad.toml").write_text('[labels]\n0 = "matrix"\n')
    with refuses(ValueError, "phases"):
        PhaseTable.read(tmp_path / "bad.toml", "silicone")


def test_connected_components_find_separate_spheres_across_the_boundary():
    """Three Al2O3 balls and one AlN ball, one of them cut by the box's faces: four
    particles, the cut one counted once, its volume that of the whole ball."""
    n, r = 40, 6.0
    lab = balls(n, [(10, 10, 10), (30, 10, 25), (0.0, 30, 30), (25, 30, 8)], r,
                labels=[1, 1, 1, 2])
    ms = microstructure_from_image(lab, TABLE, voxel_um=0.5)
    assert ms.n_particles == 4
    sizes = particle_sizes_um(ms)
    assert sorted(len(v) for v in sizes.values()) == [1, 3]
    voxels = np.bincount(ms.particle_ids.ravel())[1:]
    assert voxels.max() - voxels.min() <= 2   # the cut ball whole, like the others
    # the equivalent diameter of a voxelized ball is close to its true one (2 r h)
    for d in np.concatenate(list(sizes.values())):
        assert d == pytest.approx(2 * r * 0.5, rel=0.03)
    # the voxel fraction is close to the analytic ball volume
    f = ms.volume_fractions()["Al2O3"]
    assert f == pytest.approx(3 * 4 / 3 * math.pi * r ** 3 / n ** 3, rel=0.03)


def test_face_connectivity_only():
    """Two voxels that share an edge only are two particles (no face between them)."""
    lab = np.zeros((4, 4, 4), dtype=np.uint8)
    lab[1, 1, 1] = lab[2, 2, 1] = 1
    mid = PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone").material_ids(lab)
    assert label_particles(mid).max() == 2
    lab[2, 1, 1] = 1
    assert label_particles(PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone")
                           .material_ids(lab)).max() == 1


def test_watershed_splits_two_touching_spheres():
    """Two overlapping balls (centres 1.7 r apart) are one connected component; the
    watershed split gives two particles of nearly equal size, each on its own centre."""
    pytest.importorskip("skimage")
    n, r = 40, 7.0
    c1, c2 = (20, 20, 14.05), (20, 20, 14.05 + 1.7 * r)
    lab = balls(n, [c1, c2], r)
    table = PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone")
    assert microstructure_from_image(lab, table, voxel_um=1.0).n_particles == 1
    ms = microstructure_from_image(lab, table, voxel_um=1.0, split="watershed")
    assert ms.n_particles == 2
    voxels = np.bincount(ms.particle_ids.ravel())[1:]
    assert abs(voxels[0] - voxels[1]) <= 0.05 * voxels.sum()
    assert ms.particle_ids[20, 20, 14] != ms.particle_ids[20, 20, 26]
    # the split makes faces between two particles of one filler: a contact pair
    assert ("Al2O3", "Al2O3") in interface_pairs(ms)


def test_watershed_refused_without_scikit_image(monkeypatch):
    import builtins
    real = builtins.__import__

    def no_skimage(name, *args, **kwargs):
        if name.startswith("skimage"):
            raise ImportError(name)
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_skimage)
    lab = balls(16, [(8, 8, 8)], 4.0)
    with refuses(ValueError, "split") as info:
        microstructure_from_image(lab, PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone"),
                                  voxel_um=1.0, split="watershed")
    assert "scikit-image" in str(info.value)


def test_given_particle_labels_are_used_as_given():
    """Particle labels of any values, renumbered 1..P; two touching balls stay two."""
    n, r = 24, 5.0
    lab = balls(n, [(12, 12, 7), (12, 12, 16)], r)
    parts = balls(n, [(12, 12, 7), (12, 12, 16)], r, labels=[40, 7]).astype(np.int32)
    table = PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone")
    ms = microstructure_from_image(lab, table, voxel_um=1.0, particles=parts)
    assert ms.n_particles == 2
    assert set(np.unique(ms.particle_ids)) == {0, 1, 2}
    assert np.array_equal(ms.particle_ids == 2, parts == 40)
    wrong = parts.copy()
    wrong[0, 0, 0] = 3                                      # a particle on the matrix
    with refuses(ValueError, "particles"):
        microstructure_from_image(lab, table, voxel_um=1.0, particles=wrong)
    with refuses(ValueError, "split"):
        microstructure_from_image(lab, table, voxel_um=1.0, particles=parts,
                                  split="watershed")


def test_image_materials_ask_for_the_pairs_the_image_has():
    n, r = 24, 5.0
    lab = balls(n, [(6, 6, 6), (6, 6, 6 + 2 * r)], r, labels=[1, 2])  # Al2O3 touches AlN
    ms = microstructure_from_image(lab, TABLE, voxel_um=0.5)
    pairs = interface_pairs(ms)
    assert set(pairs) == {("Al2O3", "silicone"), ("AlN", "silicone"), ("AlN", "Al2O3")
                          [::-1]}
    k = {"silicone": 0.18, "Al2O3": 30.0, "AlN": 200.0}
    r_fm = {("Al2O3", "silicone"): 1e-8, ("AlN", "silicone"): 2e-8}
    with refuses(ValueError, "resistance") as info:
        image_materials(ms, k, r_fm)
    assert "Al2O3-AlN=VALUE" in str(info.value)
    mat = image_materials(ms, k, {**r_fm, ("AlN", "Al2O3"): 5e-8})
    assert mat.contact == "area" and mat.resistance_between("AlN", "Al2O3") == 5e-8


# ------------------------------------------------------------------ resistances, percolation
def test_resistance_items_and_an_identified_json_of_itr_reproduce():
    """PAIR=VALUE (matrix, flat names, phases holding '-') and the quoted values of a real
    identified.json (issue 58's reproduce run: the headline quotes gap)."""
    from pathlib import Path

    from itr_fv.materials.resistance_sources import (
        merge_resistances,
        parse_resistance,
        resistances_from_identified,
    )
    phases = ("silicone", "Al2O3", "Al2O3-nano")
    assert parse_resistance("Al2O3-matrix=1e-8", phases, "silicone") == (
        ("Al2O3", "silicone"), 1e-8)
    assert parse_resistance("Al2O3-nano-Al2O3=2e-8", phases, "silicone") == (
        ("Al2O3", "Al2O3-nano"), 2e-8)
    assert parse_resistance("R_Al2O3_silicone=inf", phases, "silicone")[1] == math.inf
    for bad in ("Al2O3-matrix", "Al2O3-SiC=1e-8", "matrix-matrix=1", "Al2O3-matrix=-1",
                "Gc_Al2O3_Al2O3=1e-6"):
        with refuses(ValueError, "resistance"):
            parse_resistance(bad, phases, "silicone")
    path = (Path(__file__).resolve().parents[1] / "validation" / "results" /
            "reproduce_issue58" / "identified.json")
    head = __import__("json").loads(path.read_text())["headline"]
    values, par, skipped = resistances_from_identified(path)
    assert par == head["quote"] == "gap" and skipped == []
    assert values == {n: e["best"] for n, e in head["parameters"]["gap"].items()}
    area, _, _ = resistances_from_identified(path, parametrisation="area")
    assert set(area) == {"R_Al2O3_silicone", "R_AlN_silicone", "Rff_Al2O3_Al2O3",
                         "Rff_AlN_AlN", "Rff_Al2O3_AlN"}
    with refuses(ValueError, "resistances"):
        resistances_from_identified(path, parametrisation="other")
    merged = merge_resistances([("command line", {("silicone", "Al2O3"): 1.0}),
                                ("identified", {("Al2O3", "silicone"): 2.0})])
    assert merged == {("Al2O3", "silicone"): {"value": 1.0, "source": "command line",
                                              "overridden": [{"source": "identified",
                                                              "value": 2.0}]}}


def test_percolation_of_a_rod_and_of_separate_balls():
    """A rod of filler through the box along axis 0 spans that axis only; a ball cut by the
    box's faces spans none (the image as a sample: its wrap is cut)."""
    from itr_fv.discrete.percolation import spanning_clusters
    table = PhaseTable.of({0: "matrix", 1: "Al2O3"}, "silicone")
    rod = np.zeros((16, 16, 16), dtype=np.uint8)
    rod[:, 6:9, 6:9] = 1
    ms = microstructure_from_image(rod, table, voxel_um=1.0)
    assert spanning_clusters(ms)["spans"] == [True, False, False]
    ball = balls(16, [(0.0, 0.0, 0.0)], 5.0)
    out = spanning_clusters(microstructure_from_image(ball, table, voxel_um=1.0))
    assert out["spans"] == [False, False, False] and out["clusters"] == 8
