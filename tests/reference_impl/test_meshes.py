"""Mass-spring objects from meshes: builders, signed volume, inside-out cubes, case tables."""

from __future__ import annotations

import numpy as np
import pytest

from truestep.adapters.reference import ReferenceAdapter
from truestep.cases import CaseError, load_case
from truestep.measures.properties import PROPERTIES
from truestep.reference_impl import meshes


def test_builders_count_vertices_edges_and_faces():
    assert len(meshes.triangle().edges) == 3
    tet = meshes.tetrahedron()
    assert (len(tet.vertices), len(tet.edges), len(tet.faces)) == (4, 6, 4)
    for bracing, springs in (("edges", 12), ("faces", 24), ("volume", 28)):
        c = meshes.cube(bracing=bracing)
        assert (len(c.vertices), len(c.edges), len(c.faces)) == (8, springs, 12)
    assert len(meshes.rope(5, np.zeros(3), np.ones(3)).edges) == 4
    cloth = meshes.cloth(4, 5, 0.1)
    # structural 4*4 + 3*5, shear 2*3*4, bend 4*3 + 2*5
    assert np.bincount(cloth.kind).tolist() == [31, 24, 22]


def test_mass_is_spread_evenly_and_rest_lengths_come_from_the_mesh():
    cube = meshes.cube(2.0, bracing="volume")
    mass, springs = meshes.mass_spring(cube, 4.0, 100.0, 0.5)
    assert np.all(mass == 0.5)
    lengths = sorted(set(np.round(springs.rest, 12)))
    assert lengths == pytest.approx([2.0, 2.0 * np.sqrt(2.0), 2.0 * np.sqrt(3.0)], rel=1e-12)


def test_signed_volume_of_closed_meshes():
    cube = meshes.cube(2.0, center=np.array([1.0, -3.0, 5.0]))
    assert meshes.signed_volume(cube.vertices, cube.faces) == pytest.approx(8.0, rel=1e-14)
    tet = meshes.tetrahedron(1.0)
    assert meshes.signed_volume(tet.vertices, tet.faces) == pytest.approx(1 / (6 * np.sqrt(2)), rel=1e-14)
    mirrored = cube.vertices * np.array([1.0, -1.0, 1.0])  # a reflection turns it inside out
    assert meshes.signed_volume(mirrored, cube.faces) == pytest.approx(-8.0, rel=1e-14)
    flat = cube.vertices * np.array([1.0, 0.0, 1.0])
    assert abs(meshes.signed_volume(flat, cube.faces)) < 1e-14


@pytest.mark.parametrize(("name", "inside_out"), [("cube-inside-out", True), ("cube-braced", False)])
def test_inside_out_without_diagonal_springs_and_not_with_them(case_named, name, inside_out):
    case = case_named(name)
    traj = ReferenceAdapter().simulate(case, "symplectic-euler", 0.005)
    vol = PROPERTIES["min_signed_volume"](case, traj)
    # Edge springs alone let the cube shear through flat (measured about -1.08); the
    # face and body diagonals keep it near its shape (measured 0.99).
    if inside_out:
        assert vol < -0.5
    else:
        assert vol > 0.9


def test_triangle_impulse_conserves_momentum(case_named):
    case = case_named("triangle-impulse")
    traj = ReferenceAdapter().simulate(case, "lecture", 0.01)
    p = (case.model.mass[None, :, None] * traj.v).sum(axis=1)
    # Before the impulse nothing moves; after it, only spring and damper forces act,
    # which come in equal and opposite pairs: P = F dt = 0.2 N s to round-off.
    assert np.all(p[0] == 0.0)
    assert np.allclose(p[1:], [0.2, 0.0, 0.0], rtol=0, atol=1e-14)
    assert PROPERTIES["momentum_drift"](case, traj) < 1e-13


MESH = """
kind = "particles"
[scene]
[[scene.meshes]]
kind = "cube"
size = 1.0
mass = 1.0
stiffness = 100.0
[run]
duration = 1.0
dt = [0.01]
"""


@pytest.mark.parametrize(
    ("change", "field", "reason"),
    [
        (('kind = "cube"', 'kind = "sphere"'), "scene.meshes[0].kind", "not one of"),
        (("size = 1.0", "size = -1.0"), "scene.meshes[0].size", "positive"),
        (("stiffness = 100.0", ""), "scene.meshes[0].stiffness", "missing"),
        (("mass = 1.0", "mass = 1.0\npinned = [8]"), "scene.meshes[0].pinned", "out of range"),
        (("mass = 1.0", 'mass = 1.0\nbracing = "diagonal"'), "scene.meshes[0].bracing", "not one of"),
        (("mass = 1.0", "mass = 1.0\nsides = 4"), "scene.meshes[0].sides", "unknown field"),
    ],
)
def test_bad_mesh_table_names_the_field(tmp_path, change, field, reason):
    path = tmp_path / "bad-mesh.toml"
    path.write_text(MESH.replace(*change))
    with pytest.raises(CaseError) as err:
        load_case(path)
    assert err.value.field == field
    assert reason in err.value.reason


def test_a_mesh_table_builds_springs_and_surfaces(tmp_path):
    path = tmp_path / "good-mesh.toml"
    path.write_text(MESH.replace("mass = 1.0", 'mass = 1.0\nbracing = "faces"\npinned = [0]'))
    model = load_case(path).model
    assert model.n == 8 and len(model.springs) == 24 and model.fixed.sum() == 1
    assert len(model.surfaces) == 1
    assert meshes.signed_volume(model.x0, model.surfaces[0]) == pytest.approx(1.0, rel=1e-14)
