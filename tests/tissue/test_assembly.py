"""Assembly of the layered lattice from triangle meshes."""

import numpy as np
import pytest
from tests.conftest import shared_path

from myoface.errors import MyofaceValueError
from myoface.face import read_waters_geoface
from myoface.tissue import LAYERS, TissueParams, assemble_tissue


def test_default_face_layers(default_face, default_tissue):
    m = default_tissue
    nv = default_face.n_vertices
    assert m.n_nodes == 4 * nv
    assert m.n_elements == 3 * default_face.n_triangles
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
    assert m.n_elements == 3 * face.n_triangles
    assert np.isfinite(m.rest_positions).all()


def test_bad_mesh_is_rejected():
    with pytest.raises(MyofaceValueError):
        assemble_tissue(np.zeros((3, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(MyofaceValueError):
        assemble_tissue(np.eye(3), np.array([[0, 1, 5]]))
