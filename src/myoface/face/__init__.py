"""Geometry level: the skin surface (:class:`FaceMesh`), its readers/writers and the default face."""

from myoface.face.io import (
    default_mirror_map,
    is_default_topology,
    load_default_face,
    load_mesh,
    read_waters_geoface,
    save_mesh,
)
from myoface.face.mesh import (
    FaceMesh,
    boundary_loops,
    triangle_normals,
    unique_edges,
    vertex_normals,
)

__all__ = [
    "FaceMesh",
    "boundary_loops",
    "default_mirror_map",
    "is_default_topology",
    "load_default_face",
    "load_mesh",
    "read_waters_geoface",
    "save_mesh",
    "triangle_normals",
    "unique_edges",
    "vertex_normals",
]
