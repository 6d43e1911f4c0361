"""The builder of the tissue lattice: a :class:`~myoface.tissue.model.TissueModel` under a skin
mesh, assembled automatically (Terzopoulos & Waters 1993, Section III-D), or from explicit arrays.

The layers, elements and springs it makes are described in :mod:`myoface.tissue.model`. It stands
above the model and its stiffness (the damping is set from the lattice's slowest mode, found
from the stiffness matrix), as warp.sim's ``ModelBuilder`` stands above ``Model``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import eigsh

from myoface.errors import MyofaceValueError
from myoface.face.mesh import triangle_normals, unique_edges, vertex_normals
from myoface.tissue.forces import LAW_CONTINUOUS, LAW_PAPER, element_volumes_numpy
from myoface.tissue.hessian import stiffness_matrix
from myoface.tissue.model import LAYERS, LayerMaterial, TissueModel, TissueParams

#: lightest node mass as a fraction of the median (keeps the explicit time step reasonable)
MASS_FLOOR = 0.25
#: a prism whose rest volume is below this fraction of (top area x layer thickness) is treated as
#: inverted and the layers under its vertices are thinned
MIN_REL_VOLUME = 0.2
#: the spring laws by the name :attr:`TissueParams.biphasic` gives them
SPRING_LAWS = {"continuous": LAW_CONTINUOUS, "paper": LAW_PAPER}


def _smooth_normals(vertices, triangles, passes):
    n = vertex_normals(vertices, triangles)
    if passes <= 0:
        return n
    edges = unique_edges(triangles)
    for _ in range(passes):
        acc = n.copy()
        np.add.at(acc, edges[:, 0], n[edges[:, 1]])
        np.add.at(acc, edges[:, 1], n[edges[:, 0]])
        n = acc / np.linalg.norm(acc, axis=1, keepdims=True)
    return n


def _order_free_volumes(pos: np.ndarray, elems: np.ndarray) -> np.ndarray:
    """Prism volumes averaged over the 6 vertex orders of their triangles.

    A prism's split into three tetrahedra depends on which vertex comes first; averaging over
    all orders makes the thickness reduction below independent of it, so a mirror-symmetric
    mesh gets a mirror-symmetric lattice.
    """
    vol = np.zeros(len(elems))
    for perm, sgn in (
        ((0, 1, 2), 1),
        ((1, 2, 0), 1),
        ((2, 0, 1), 1),
        ((0, 2, 1), -1),
        ((2, 1, 0), -1),
        ((1, 0, 2), -1),
    ):
        cols = list(perm) + [q + 3 for q in perm]
        vol += sgn * element_volumes_numpy(pos, elems[:, cols])
    return vol / 6.0


def assemble_tissue(
    vertices: np.ndarray, triangles: np.ndarray, params: TissueParams | None = None
) -> TissueModel:
    """Build the layered lattice under a skin mesh, automatically (T&W 1993, Section III-D).

    Parameters
    ----------
    vertices : (V, 3) float ndarray — skin positions, mm, outward-oriented mesh.
    triangles : (F, 3) int ndarray — counter-clockwise seen from outside.
    params : TissueParams, optional

    Returns
    -------
    TissueModel
        With the bone layer kinematic. Where the layers would cross (sharp creases, thin
        features), the local thickness is reduced until every element has positive volume.
    """
    params = params or TissueParams()
    v = np.asarray(vertices, dtype=np.float64)
    t = np.asarray(triangles, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise MyofaceValueError(f"vertices must be a finite (V, 3) array; got shape {v.shape}")
    if t.ndim != 2 or t.shape[1] != 3 or t.min() < 0 or t.max() >= len(v):
        raise MyofaceValueError("triangles must be an (F, 3) array of valid vertex indices")
    nv = len(v)
    normals = _smooth_normals(v, t, params.normal_smoothing)
    depths = params.depths_mm

    elems = np.concatenate(
        [np.concatenate([t + k * nv, t + (k + 1) * nv], axis=1) for k in range(3)]
    )
    elem_layer = np.repeat(np.array([1, 2, 3], np.int8), len(t))

    # offset the layers; where they would cross (sharp creases, thin features such as the lid
    # and lip margins), shrink the local thickness until every prism keeps a sane volume
    layer_d = np.diff(depths)[elem_layer - 1]
    top_area = 0.5 * np.linalg.norm(triangle_normals(v, t, unit=False), axis=1)
    top_area = np.tile(top_area, 3)
    # triangles that face against their own vertex normals (folds in the source mesh) give
    # inverted prisms at any thickness: they keep their signed rest volume and are not thinned
    tri_n = triangle_normals(v, t)
    folded = np.tile(np.einsum("ij,ij->i", tri_n, normals[t].mean(axis=1)) < 0.2, 3)
    scale = np.ones(nv)
    for _ in range(60):
        pos = np.concatenate([v - (scale * d)[:, None] * normals for d in depths])
        vol = -_order_free_volumes(pos, elems)  # outward winding: deeper prisms are negative
        expected = top_area * layer_d * scale[elems[:, :3] % nv].mean(axis=1)
        bad = (vol < MIN_REL_VOLUME * expected) & ~folded
        if not bad.any():
            break
        scale[np.unique(elems[bad] % nv)] *= 0.85
    else:
        raise MyofaceValueError(
            f"cannot build tissue layers under this mesh: {int(bad.sum())} elements stay inverted "
            "(is the mesh consistently oriented, normals pointing out of the head?)"
        )
    sign = -1.0
    # the rest volume as the force kernels measure it (their fixed tetrahedral split)
    vol = sign * element_volumes_numpy(pos, elems)

    # springs
    edges = unique_edges(t)
    a, b = edges[:, 0], edges[:, 1]
    ii, jj, mm = [], [], []

    def add(i, j, m):
        ii.append(i)
        jj.append(j)
        mm.append(np.full(len(i), m, np.int64))

    add(a, b, 0)  # epidermis: the skin triangle edges
    for k, m in ((0, 1), (1, 2), (2, 3)):  # dermis, fat, muscle elements
        top, bot = k * nv, (k + 1) * nv
        add(np.arange(nv) + top, np.arange(nv) + bot, m)  # vertical
        add(a + top, b + bot, m)  # shear diagonals of each side face
        add(b + top, a + bot, m)
        if k < 2:
            add(a + bot, b + bot, m)  # the lower triangle's edges (not bone)
    si, sj, smat = np.concatenate(ii), np.concatenate(jj), np.concatenate(mm)
    rest = np.linalg.norm(pos[sj] - pos[si], axis=1)

    # volume weights: kv = volume * alpha / A^2, A = mean area of the prism's two triangles
    area_top = 0.5 * np.linalg.norm(triangle_normals(pos, elems[:, :3], unit=False), axis=1)
    area_bot = 0.5 * np.linalg.norm(triangle_normals(pos, elems[:, 3:], unit=False), axis=1)
    area = np.maximum(0.5 * (area_top + area_bot), 1e-6)
    layer_mat = [params.dermis, params.fat, params.muscle]
    vol_w = (
        np.array([layer_mat[k - 1].volume * layer_mat[k - 1].alpha for k in elem_layer]) / area**2
    )

    # lumped masses: each element gives density * V / 6 to each of its nodes; the skin nodes
    # get at least the dermis share so no free node is massless
    mass = np.zeros(len(pos))
    np.add.at(mass, elems.reshape(-1), np.repeat(params.density * vol / 6.0, 6))
    # nodes of tiny triangles get a floor mass (MASS_FLOOR x median) so the explicit time step is
    # not dictated by a few slivers
    mass = np.maximum(mass, MASS_FLOOR * np.median(mass))

    if params.biphasic not in SPRING_LAWS:
        raise MyofaceValueError(
            f"biphasic must be one of {tuple(SPRING_LAWS)}; got {params.biphasic!r}"
        )
    node_layer = np.repeat(np.arange(4, dtype=np.int8), nv)
    model = TissueModel(
        rest_positions=pos,
        n_vertices=nv,
        skin_triangles=t,
        node_layer=node_layer,
        spring_i=si,
        spring_j=sj,
        rest_length=rest,
        spring_material=smat,
        materials=params.materials(),
        elements=elems,
        element_layer=elem_layer,
        rest_volume=vol,
        volume_weight=vol_w,
        volume_sign=sign,
        mass=mass,
        damping=np.zeros(len(pos)),
        kinematic=node_layer == 3,
        spring_law=SPRING_LAWS[params.biphasic],
        params=params,
    )
    # mass-proportional damping from the slowest mode of the undamped lattice (TissueParams)
    return replace(model, damping=2.0 * params.damping_ratio * lowest_frequency(model) * mass)


def bind_layer(model: TissueModel, vertices, layer: str, material: LayerMaterial) -> TissueModel:
    """A copy of ``model`` in which the springs of element layer ``layer`` ("dermis", "fat" or
    "muscle") under ``vertices`` (skin vertex indices; both ends of a spring under one of them)
    take ``material`` instead of the layer's own: e.g. where the mimetic muscles insert into
    the dermis and there is no mobile fat between (the lips, the chin). The material is
    appended as a row of :attr:`TissueModel.materials`; the damping is left as it was."""
    k = LAYERS.index(layer)
    if k == 0:
        raise MyofaceValueError("bind_layer binds an element layer, not the epidermis")
    nv = model.n_vertices
    under = np.zeros(nv, bool)
    under[np.asarray(vertices, dtype=np.int64)] = True
    sel = (model.spring_material == k) & under[model.spring_i % nv] & under[model.spring_j % nv]
    mats = np.vstack([model.materials, [material.alpha, material.beta, material.strain_c]])
    smat = model.spring_material.copy()
    smat[sel] = len(mats) - 1
    return replace(model, materials=mats, spring_material=smat)


def lowest_frequency(model: TissueModel) -> float:
    """omega_min (rad/s): the slowest natural mode of the lattice at rest (K v = w^2 M v)."""
    k = stiffness_matrix(model, model.rest_positions).tocsc()
    m = np.repeat(model.mass[model.free_index], 3)
    # symmetric form M^-1/2 K M^-1/2, smallest eigenvalue by shift-invert about 0
    s = sp.diags(1.0 / np.sqrt(m))
    w2 = eigsh((s @ k @ s).tocsc(), k=1, sigma=0.0, which="LM", return_eigenvectors=False)[0]
    return float(np.sqrt(max(w2, 0.0)))


def make_lattice(
    positions,
    springs,
    *,
    materials=None,
    spring_material=None,
    mass=1.0,
    damping=0.0,
    kinematic=None,
    elements=None,
    volume_weight=0.0,
    biphasic: str = "continuous",
) -> TissueModel:
    """A TissueModel from explicit arrays — for tests, benchmarks and non-face lattices.

    Parameters
    ----------
    positions : (N, 3) float — rest positions, mm.
    springs : (S, 2) int — node pairs; rest lengths are taken from ``positions``.
    materials : (M, 3) float, optional — [alpha, beta, strain_c] rows (default one row
        [1000, 10000, 0.2]).
    spring_material : (S,) int, optional — default all 0.
    mass, damping : float or (N,) — g and g/s.
    kinematic : (N,) bool, optional — prescribed nodes (default none).
    elements : (E, 6) int, optional — prisms [a0, b0, c0, a1, b1, c1]; volume_weight kv per element.
    """
    pos = np.asarray(positions, dtype=np.float64)
    sp_ = np.asarray(springs, dtype=np.int64).reshape(-1, 2)
    n = len(pos)
    mats = np.asarray(materials if materials is not None else [[1000.0, 10000.0, 0.2]], np.float64)
    smat = (
        np.zeros(len(sp_), np.int64)
        if spring_material is None
        else np.asarray(spring_material, np.int64)
    )
    el = np.zeros((0, 6), np.int64) if elements is None else np.asarray(elements, np.int64)
    vol = element_volumes_numpy(pos, el) if len(el) else np.zeros(0)
    sign = 1.0 if (len(vol) == 0 or np.median(vol) > 0) else -1.0
    return TissueModel(
        rest_positions=pos,
        n_vertices=n,
        skin_triangles=np.zeros((0, 3), np.int64),
        node_layer=np.zeros(n, np.int8),
        spring_i=sp_[:, 0].copy(),
        spring_j=sp_[:, 1].copy(),
        rest_length=np.linalg.norm(pos[sp_[:, 1]] - pos[sp_[:, 0]], axis=1),
        spring_material=smat,
        materials=mats,
        elements=el,
        element_layer=np.ones(len(el), np.int8),
        rest_volume=sign * vol,
        volume_weight=np.broadcast_to(np.asarray(volume_weight, float), (len(el),)).copy(),
        volume_sign=sign,
        mass=np.broadcast_to(np.asarray(mass, float), (n,)).copy(),
        damping=np.broadcast_to(np.asarray(damping, float), (n,)).copy(),
        kinematic=np.zeros(n, bool) if kinematic is None else np.asarray(kinematic, bool).copy(),
        spring_law=SPRING_LAWS[biphasic],
    )
