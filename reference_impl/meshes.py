"""Mass-spring-damper objects built from a mesh, as the lecture builds them.

"Model each vertex as a point mass; model each edge as a spring with a paired damper;
each spring's rest length is set equal to the original length of the edge; a mass is
assigned to the object and evenly distributed among its vertices; spring constants are
assigned uniformly." Builders return a :class:`Mesh` (vertices, edges and, for closed
meshes, outward-oriented triangles); :func:`mass_spring` turns one into masses and
springs. A cube of edge springs alone can shear flat and turn inside out; springs across
its faces and its volume keep its shape, and :func:`signed_volume` tells which happened.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from truestep.reference_impl.model import Springs

CUBE_BRACING = ("edges", "faces", "volume")
"""Cube spring sets: edges only; plus face diagonals; plus face and volume diagonals."""
CLOTH_KINDS = ("structural", "shear", "bend")
"""Cloth spring kinds, the values of ``Mesh.kind`` for a cloth grid."""


@dataclass
class Mesh:
    """A mesh as the mass-spring builder sees it.

    vertices : ndarray, shape (n, 3), m
    edges : ndarray of int, shape (m, 2)           one spring each
    faces : ndarray of int, shape (k, 3), or None  closed surface, outward (counter-
        clockwise seen from outside); ``None`` for open meshes
    kind : ndarray of int, shape (m,)              spring kind per edge (cloth: index
        into :data:`CLOTH_KINDS`; 0 elsewhere)
    """

    vertices: np.ndarray
    edges: np.ndarray
    faces: np.ndarray | None = None
    kind: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.kind is None:
            self.kind = np.zeros(len(self.edges), dtype=int)


def mass_spring(
    mesh: Mesh, mass: float, stiffness: float | np.ndarray, damping: float | np.ndarray = 0.0
) -> tuple[np.ndarray, Springs]:
    """Point masses and edge springs of ``mesh``.

    mass : kg, the whole object's, spread evenly over the vertices;
    stiffness (N/m) and damping (N s/m): one value for every spring, or one per edge.
    Returns the masses (n,) and the springs (local vertex numbers), rest lengths taken
    from the mesh.
    """
    n, m = len(mesh.vertices), len(mesh.edges)
    i, j = mesh.edges[:, 0].copy(), mesh.edges[:, 1].copy()
    rest = np.linalg.norm(mesh.vertices[i] - mesh.vertices[j], axis=1)
    springs = Springs(
        i,
        j,
        np.broadcast_to(np.asarray(stiffness, float), (m,)).copy(),
        np.broadcast_to(np.asarray(damping, float), (m,)).copy(),
        rest,
    )
    return np.full(n, mass / n), springs


def signed_volume(x: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Signed volume enclosed by triangles ``faces`` (k, 3) at positions ``x`` (..., n, 3), m^3.

    ``V = sum (a . (b x c)) / 6`` over the triangles ``(a, b, c)``: positive for an
    outward-oriented closed surface, zero when it has collapsed flat, negative once it
    has turned inside out. Works on one state (n, 3) or a whole trajectory (T, n, 3).
    """
    a, b, c = x[..., faces[:, 0], :], x[..., faces[:, 1], :], x[..., faces[:, 2], :]
    return np.einsum("...i,...i->...", a, np.cross(b, c)).sum(axis=-1) / 6.0


def _orient_outward(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Flip triangles of a convex mesh whose normal points toward its centroid."""
    centroid = vertices.mean(axis=0)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - centroid) < 0
    faces = faces.copy()
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces


def triangle(side: float = 1.0, center: np.ndarray | None = None) -> Mesh:
    """The lecture's equilateral triangle in the x-y plane: ``V1, V2, V3`` are vertices 0, 1, 2.

    ``V1`` bottom left, ``V2`` at the top, ``V3`` bottom right; edges ``E12, E23, E31``.
    Centred (centroid) on ``center`` (default origin); side in m.
    """
    h = side * np.sqrt(3.0) / 2.0
    v = np.array([[-side / 2, -h / 3, 0.0], [0.0, 2 * h / 3, 0.0], [side / 2, -h / 3, 0.0]])
    center = np.zeros(3) if center is None else np.asarray(center, float)
    return Mesh(v + center, np.array([[0, 1], [1, 2], [2, 0]]))


def tetrahedron(size: float = 1.0, center: np.ndarray | None = None) -> Mesh:
    """A regular tetrahedron of edge ``size`` (m): 4 vertices, 6 edges, 4 faces."""
    v = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
    v *= size / (2.0 * np.sqrt(2.0))
    center = np.zeros(3) if center is None else np.asarray(center, float)
    v += center
    edges = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
    faces = _orient_outward(v, np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]))
    return Mesh(v, edges, faces)


def cube(size: float = 1.0, center: np.ndarray | None = None, bracing: str = "edges") -> Mesh:
    """An axis-aligned cube of edge ``size`` (m) around ``center``.

    Vertex ``ix + 2 iy + 4 iz`` sits at ``center + size (ix - 1/2, iy - 1/2, iz - 1/2)``: the
    bottom face (lowest y) is vertices 0, 1, 4, 5 and the top face 2, 3, 6, 7.
    ``bracing``: ``"edges"`` (12 springs), ``"faces"`` (plus both diagonals of every face,
    24), ``"volume"`` (plus the 4 body diagonals, 28). Faces: the 12 triangles of its
    six squares, outward.
    """
    if bracing not in CUBE_BRACING:
        raise ValueError(f"cube: bracing {bracing!r} is not one of {', '.join(CUBE_BRACING)}")
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)])
    center = np.zeros(3) if center is None else np.asarray(center, float)
    v = center + size * (bits - 0.5)
    diff = np.abs(bits[:, None, :] - bits[None, :, :]).sum(axis=2)  # Hamming distance
    i, j = np.triu_indices(8, 1)
    hamming = diff[i, j]
    keep = {"edges": 1, "faces": 2, "volume": 3}[bracing]
    sel = hamming <= keep
    edges = np.stack([i[sel], j[sel]], axis=1)
    kind = hamming[sel] - 1  # 0 edge, 1 face diagonal, 2 body diagonal
    quads = [cube_face(axis, side) for axis in range(3) for side in (0, 1)]
    tris = np.array([[q[0], q[1], q[2]] for q in quads] + [[q[0], q[2], q[3]] for q in quads])
    return Mesh(v, edges, _orient_outward(v, tris), kind)


def cube_face(axis: int, side: int) -> list[int]:
    """The four vertices of a cube face (``bits[axis] == side``) in order around it."""
    others = [a for a in range(3) if a != axis]
    ring = [(0, 0), (1, 0), (1, 1), (0, 1)]
    face = []
    for p, q in ring:
        bits = [0, 0, 0]
        bits[axis], bits[others[0]], bits[others[1]] = side, p, q
        face.append(bits[0] + 2 * bits[1] + 4 * bits[2])
    return face


def rope(n: int, start: np.ndarray, end: np.ndarray) -> Mesh:
    """A chain of ``n >= 2`` vertices evenly spaced from ``start`` to ``end`` (m), n - 1 links."""
    if n < 2:
        raise ValueError(f"rope: needs at least 2 vertices, got {n}")
    s = np.linspace(0.0, 1.0, n)[:, None]
    v = np.asarray(start, float) + s * (np.asarray(end, float) - np.asarray(start, float))
    k = np.arange(n - 1)
    return Mesh(v, np.stack([k, k + 1], axis=1))


def cloth(
    rows: int,
    cols: int,
    spacing: float,
    origin: np.ndarray | None = None,
    u: np.ndarray | None = None,
    w: np.ndarray | None = None,
) -> Mesh:
    """A ``rows x cols`` grid of vertices ``spacing`` (m) apart, with the three spring kinds.

    Vertex ``r * cols + c`` sits at ``origin + c spacing u + r spacing w``, ``u`` and ``w``
    unit vectors (default ``u = +x``, ``w = -z``: the x-z plane). Springs: structural
    (neighbours along rows and columns), shear (both diagonals of every cell), bend (two
    apart along rows and columns); ``Mesh.kind`` indexes :data:`CLOTH_KINDS`.
    """
    if rows < 2 or cols < 2:
        raise ValueError(f"cloth: needs at least 2 x 2 vertices, got {rows} x {cols}")
    origin = np.zeros(3) if origin is None else np.asarray(origin, float)
    u = np.array([1.0, 0.0, 0.0]) if u is None else np.asarray(u, float)
    w = np.array([0.0, 0.0, -1.0]) if w is None else np.asarray(w, float)
    r, c = np.divmod(np.arange(rows * cols), cols)
    v = origin + spacing * (c[:, None] * u + r[:, None] * w)
    idx = np.arange(rows * cols).reshape(rows, cols)

    def pairs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.stack([a.ravel(), b.ravel()], axis=1)

    structural = np.concatenate([pairs(idx[:, :-1], idx[:, 1:]), pairs(idx[:-1, :], idx[1:, :])])
    shear = np.concatenate([pairs(idx[:-1, :-1], idx[1:, 1:]), pairs(idx[:-1, 1:], idx[1:, :-1])])
    bend = np.concatenate([pairs(idx[:, :-2], idx[:, 2:]), pairs(idx[:-2, :], idx[2:, :])])
    edges = np.concatenate([structural, shear, bend])
    kind = np.repeat([0, 1, 2], [len(structural), len(shear), len(bend)])
    return Mesh(v, edges, None, kind)
