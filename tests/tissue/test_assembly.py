"""Assembly of the layered lattice from triangle meshes."""

import numpy as np
import pytest
from tests.conftest import shared_path

from myoface.errors import MyofaceValueError
from myoface.face import read_waters_geoface
from myoface.face.mesh import unique_edges
from myoface.tissue import LAYERS, TissueParams, assemble_tissue


def _tet6(p0, p1, p2, p3):
    """6 x the signed volumes of tetrahedra (rows)."""
    return np.einsum("ij,ij->i", p1 - p0, np.cross(p2 - p0, p3 - p0))


def assert_prisms_fill_the_layers(m, triangles):
    """Each element layer's prisms fill the solid between its two node surfaces: their rest
    volumes add up to the volume that solid encloses (divergence theorem over its top, bottom and
    rim), so no triangle lacks its prism, none has two, none is inverted or mis-signed.

    Tolerance, exact rather than tuned: a prism's three tetrahedra cut each of its quadrilateral
    side faces along one diagonal, and the two prisms that share a face (or the rim's two
    triangles here) may cut it along different ones; they then differ by the tetrahedron on the
    face's four corners. So the two volumes differ by at most the sum of those over all faces."""
    x, nv = m.rest_positions, m.n_vertices
    t = np.asarray(triangles)
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    paired = {(a, b) for a, b in edges}
    rim = np.array([(a, b) for a, b in edges if (b, a) not in paired])
    ue = unique_edges(t)
    for k in (1, 2, 3):
        top, bot = (k - 1) * nv, k * nv
        tri = [x[t[:, q] + top] for q in range(3)]
        low = [x[t[:, q] + bot] for q in range(3)]
        origin = np.zeros_like(tri[0])
        enclosed = _tet6(origin, *tri).sum() - _tet6(origin[: len(t)], *low).sum()
        a, b = rim[:, 0], rim[:, 1]
        o = np.zeros((len(rim), 3))
        enclosed += _tet6(o, x[a + top], x[a + bot], x[b + bot]).sum()
        enclosed += _tet6(o, x[a + top], x[b + bot], x[b + top]).sum()
        enclosed /= 6.0
        a, b = ue[:, 0], ue[:, 1]
        slack = np.abs(_tet6(x[a + top], x[b + top], x[a + bot], x[b + bot])).sum() / 6.0
        total = m.rest_volume[m.element_layer == k].sum()
        assert enclosed > 0
        assert abs(total - enclosed) <= slack, (k, total, enclosed, slack)


def test_default_face_layers(default_face, default_tissue):
    m = default_tissue
    nv = default_face.n_vertices
    assert m.n_nodes == 4 * nv
    assert_prisms_fill_the_layers(m, default_face.triangles)
    np.testing.assert_array_equal(m.rest_positions[:nv], default_face.vertices)
    # each deeper layer lies under the skin, along the inward normal, at most its nominal depth
    depth = np.einsum(
        "ij,ij->i", default_face.vertices - m.rest_positions[3 * nv :], default_face.vertex_normals
    )
    assert depth.max() <= TissueParams().depths_mm[-1] + 1e-9
    assert np.median(depth) > 0.8 * TissueParams().depths_mm[-1]
    assert (m.rest_volume > 0).all()
    assert set(np.unique(m.spring_material)) == set(range(len(LAYERS)))
    assert m.kinematic.sum() == nv and m.kinematic[3 * nv :].all()
    assert (m.rest_length > 0).all()
    # damping is positive, masses are positive
    assert (m.mass > 0).all() and (m.damping > 0).all()


def test_waters_geoface_assembles():
    face = read_waters_geoface(shared_path("waters-geoface"))
    m = assemble_tissue(face.vertices, face.triangles)
    print(
        f"\nWaters geoface lattice: {m.summary()} "
        "(the paper's: about 960 elements and 6,500 springs)"
    )
    assert_prisms_fill_the_layers(m, face.triangles)
    assert np.isfinite(m.rest_positions).all()


def test_bad_mesh_is_rejected():
    with pytest.raises(MyofaceValueError):
        assemble_tissue(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(MyofaceValueError):
        assemble_tissue(np.eye(3), np.array([[0, 1, 5]]))
