"""Writing a face animation as one binary glTF 2.0 file (``.glb``) with pygltflib, and reading
its skin back.

The file's scene (units metres, axes as glTF wants them: +Y up, +Z the face's front, +X the
subject's left; the model's own frame in millimetres has the same axes, so the only change is
the scale by 1/1000)::

    myoface_head            the root; its rotation and translation: the head pose of a video
      skin                  the skin mesh (UVs, texture) and, as a second primitive, the eye
                            sockets and the mouth cavity the renderer draws, both moved by the
                            morph targets (muscles, then correctives); the lids are skin
      eye_l, eye_r          the eyeballs, each at its centre, turned by the gaze
      teeth_upper           fixed in the head
      teeth_lower, tongue   turned and slid by the jaw (the mandible's rigid motion)

One animation, ``myoface``, at the clip's frame rate: the skin's morph weights, the eyes'
rotations, the jaw's rotation and translation on the lower teeth and the tongue, and the head
pose on the root (a video's CSV only). Colours are linear (glTF's COLOR_0), the texture sRGB.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceFormatError, MyofaceValueError

#: metres per millimetre: the model works in mm, glTF in m
M_PER_MM = 1e-3
#: the animation's name in the file
ANIMATION_NAME = "myoface"
SKIN_NODE = "skin"
ROOT_NODE = "myoface_head"
_F32 = 5126  # FLOAT
_U32 = 5125  # UNSIGNED_INT
_ARRAY, _ELEMENTS = 34962, 34963


def _pygltflib():
    try:
        import pygltflib
    except ImportError:
        from myoface.errors import MyofaceDependencyError

        raise MyofaceDependencyError(
            "glTF export needs pygltflib: pip install 'pygltflib>=1.16,<2'"
        ) from None
    return pygltflib


class _Blob:
    """The file's one binary buffer, its buffer views and accessors."""

    def __init__(self, g):
        self.g = g
        self.data = bytearray()

    def view(self, raw: bytes, target=None) -> int:
        gl = _pygltflib()
        self.data.extend(b"\0" * (-len(self.data) % 4))
        self.g.bufferViews.append(
            gl.BufferView(buffer=0, byteOffset=len(self.data), byteLength=len(raw), target=target)
        )
        self.data.extend(raw)
        return len(self.g.bufferViews) - 1

    def accessor(self, a, type_: str, *, target=None, minmax: bool = False, ints: bool = False):
        gl = _pygltflib()
        arr = np.ascontiguousarray(a, dtype=np.uint32 if ints else np.float32)
        n = len(arr)
        flat = arr.reshape(n, -1)
        kw = {}
        if minmax:
            kw = {"min": flat.min(axis=0).tolist(), "max": flat.max(axis=0).tolist()}
        self.g.accessors.append(
            gl.Accessor(
                bufferView=self.view(arr.tobytes(), target),
                componentType=_U32 if ints else _F32,
                count=n,
                type=type_,
                **kw,
            )
        )
        return len(self.g.accessors) - 1


def _normals(v: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Unit area-weighted vertex normals (the renderer's kernel); a vertex of no triangle gets +z."""
    from myoface.render.raster import vertex_normals_numba

    out = np.empty_like(np.ascontiguousarray(v, dtype=np.float64))
    vertex_normals_numba(
        np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(tris, dtype=np.int64), out
    )
    bad = ~(np.linalg.norm(out, axis=1) > 0.5)
    out[bad] = (0.0, 0.0, 1.0)
    return out


def _quat(rot: np.ndarray) -> np.ndarray:
    """glTF's (x, y, z, w) unit quaternion of a rotation matrix."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(rot, dtype=np.float64)).as_quat()


def _quats(rots) -> np.ndarray:
    """(T, 4) quaternions, each on the same side as the one before (so that interpolation takes
    the short way)."""
    q = np.array([_quat(r) for r in rots])
    for k in range(1, len(q)):
        if q[k] @ q[k - 1] < 0:
            q[k] = -q[k]
    return q


@dataclass(frozen=True)
class _Part:
    """A rigid part: vertices (N, 3) mm in the head frame, triangles, normals, linear colours."""

    name: str
    vertices: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    origin: np.ndarray  # where its node stands (mm, head frame); vertices are stored from it


def _split_tongue(lower) -> tuple[tuple, tuple]:
    """The renderer's lower mouth mesh (lower teeth + tongue, the tongue last) as two meshes."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    v, t, n, col = lower
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(v), len(v)))
    _, lab = connected_components(g, directed=False)
    tongue = lab == lab[-1]

    def part(mask):
        idx = np.full(len(v), -1)
        idx[mask] = np.arange(mask.sum())
        keep = mask[t].all(axis=1)
        return v[mask], idx[t[keep]], n[mask], col[mask]

    return part(~tongue), part(tongue)


def _rigid_parts(model) -> tuple[list, list, list]:
    """(eyes, fixed, jaw) parts as the renderer draws them (:mod:`myoface.render.dressing`,
    :mod:`myoface.render.mouth`)."""
    from myoface.face.eyes import eyeball_center
    from myoface.render import dressing, mouth

    face = model.face
    eyes = []
    for op in dressing.find_openings(face):
        if not op.name.startswith("eye"):
            continue
        c = eyeball_center(face.vertices, op.loop)
        v, t, nrm, col = dressing.eyeball(c, np.array([0.0, 0.0, 1.0]), dressing.EYE_RADIUS_MM)
        eyes.append(_Part(op.name, v, t, nrm, col, c))
    fixed, jaw = [], []
    if model.dentition is not None:
        mm = mouth.mouth_meshes(model.dentition)
        zero = np.zeros(3)
        fixed.append(_Part("teeth_upper", *mm.upper, zero))
        lower, tongue = _split_tongue(mm.lower)
        jaw.append(_Part("teeth_lower", *lower, zero))
        jaw.append(_Part("tongue", *tongue, zero))
    return eyes, fixed, jaw


class _Dressing:
    """The renderer's sockets and mouth cavity: vertices that follow the skin (affine in its
    positions, so a morph target of the skin gives theirs exactly)."""

    def __init__(self, model):
        from myoface.render import Renderer
        from myoface.synth import make_camera

        face = model.face
        r = Renderer(face, make_camera(face.vertices, "front", 16, 16), ssaa=1, wrinkles=False)
        sc = r.scene
        self.renderer = r
        self.lo, self.hi = sc.n_face, sc.n_dynamic
        tris = np.asarray(sc.dyn_tris[face.n_triangles :]) - self.lo
        self.triangles = tris if len(tris) and tris.min() >= 0 else np.zeros((0, 3), np.int64)
        self.colors = np.asarray(sc.vcol[self.lo : self.hi])
        self.texture = r.texture  # linear float32 (H, W, 3) or None: what the renderer maps

    @property
    def n_vertices(self) -> int:
        return self.hi - self.lo

    def positions(self, skin: np.ndarray) -> np.ndarray:
        return self.renderer.positions(skin)[self.lo : self.hi]


def _png(image_srgb8: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image_srgb8)).save(buf, format="PNG")
    return buf.getvalue()


def write_glb(path: str | os.PathLike, model, clip, sim, morph) -> Path:
    """Write ``clip`` (:class:`~myoface.export.clip.Clip`) as simulated (``sim``,
    :class:`~myoface.export.clip.SimulatedClip`) with the skin's morph targets ``morph``
    (:class:`~myoface.export.morph.MorphAnimation`) to the binary glTF ``path`` (written
    whole or not at all); returns the path. See the module's docstring for what is in it."""
    from myoface import __version__
    from myoface._io import atomic_output
    from myoface.render.renderer import gaze_rotation, to_srgb8

    gl = _pygltflib()
    face = model.face
    g = gl.GLTF2(
        asset=gl.Asset(
            version="2.0",
            generator=f"myoface {__version__}",
            extras={
                "source": clip.source,
                "fps": clip.fps,
                "frames": clip.n_frames,
                "units": "metres; +Y up, +Z the face's front, +X the subject's left",
                "morph_targets": {
                    "muscles": morph.n_muscle_targets,
                    "correctives": morph.n_targets - morph.n_muscle_targets,
                },
                "max_frame_rms_mm": float(morph.frame_rms_mm.max()),
            },
        ),
        scene=0,
    )
    blob = _Blob(g)
    s = M_PER_MM
    n_targets = morph.n_targets

    # ---------------------------------------------------------------- materials
    dress = _Dressing(model)
    skin_mat = gl.Material(
        name="skin",
        doubleSided=True,
        pbrMetallicRoughness=gl.PbrMetallicRoughness(metallicFactor=0.0, roughnessFactor=0.6),
    )
    if dress.texture is not None and face.uv is not None:
        # the same texture for every export of this model: encoded once
        png = model.memo(("export.texture_png",), lambda: _png(to_srgb8(dress.texture)))
        img = blob.view(png)
        g.images.append(gl.Image(bufferView=img, mimeType="image/png", name="skin"))
        g.samplers.append(gl.Sampler(magFilter=9729, minFilter=9987, wrapS=33071, wrapT=33071))
        g.textures.append(gl.Texture(sampler=0, source=0, name="skin"))
        skin_mat.pbrMetallicRoughness.baseColorTexture = gl.TextureInfo(index=0)
    g.materials.append(skin_mat)

    def colour_material(name, roughness):
        g.materials.append(
            gl.Material(
                name=name,
                doubleSided=True,
                pbrMetallicRoughness=gl.PbrMetallicRoughness(
                    metallicFactor=0.0, roughnessFactor=roughness
                ),
            )
        )
        return len(g.materials) - 1

    # ---------------------------------------------------------------- the skin and its targets
    rest = np.asarray(morph.rest, dtype=np.float64)
    tris = np.asarray(face.triangles, dtype=np.int64)
    attrs = gl.Attributes(
        POSITION=blob.accessor(rest * s, "VEC3", target=_ARRAY, minmax=True),
        NORMAL=blob.accessor(_normals(rest, tris), "VEC3", target=_ARRAY),
    )
    if face.uv is not None:
        uv = np.asarray(face.uv, dtype=np.float64).copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # glTF's v runs down the image, the face's up
        attrs.TEXCOORD_0 = blob.accessor(uv, "VEC2", target=_ARRAY)
    n0 = _normals(rest, tris)
    skin_targets = []
    for d in morph.targets:
        skin_targets.append(
            {
                "POSITION": blob.accessor(d * s, "VEC3", target=_ARRAY, minmax=True),
                "NORMAL": blob.accessor(_normals(rest + d, tris) - n0, "VEC3", target=_ARRAY),
            }
        )
    prims = [
        gl.Primitive(
            attributes=attrs,
            indices=blob.accessor(tris.reshape(-1), "SCALAR", target=_ELEMENTS, ints=True),
            material=0,
            targets=skin_targets or None,
        )
    ]
    if dress.n_vertices and len(dress.triangles):
        d_rest = dress.positions(rest)
        dn0 = _normals(d_rest, dress.triangles)
        d_targets = []
        for d in morph.targets:
            moved = dress.positions(rest + d)
            d_targets.append(
                {
                    "POSITION": blob.accessor(
                        (moved - d_rest) * s, "VEC3", target=_ARRAY, minmax=True
                    ),  # fmt: skip
                    "NORMAL": blob.accessor(
                        _normals(moved, dress.triangles) - dn0, "VEC3", target=_ARRAY
                    ),
                }
            )
        prims.append(
            gl.Primitive(
                attributes=gl.Attributes(
                    POSITION=blob.accessor(d_rest * s, "VEC3", target=_ARRAY, minmax=True),
                    NORMAL=blob.accessor(dn0, "VEC3", target=_ARRAY),
                    COLOR_0=blob.accessor(dress.colors, "VEC3", target=_ARRAY),
                ),
                indices=blob.accessor(
                    dress.triangles.reshape(-1), "SCALAR", target=_ELEMENTS, ints=True
                ),
                material=colour_material("sockets_and_mouth", 0.9),
                targets=d_targets or None,
            )
        )
    g.meshes.append(
        gl.Mesh(
            name="skin",
            primitives=prims,
            weights=[0.0] * n_targets if n_targets else None,
            extras={"targetNames": list(morph.names)} if n_targets else None,
        )
    )
    g.nodes.append(gl.Node(name=ROOT_NODE, children=[]))
    root = g.nodes[0]

    def add_node(node) -> int:
        g.nodes.append(node)
        root.children.append(len(g.nodes) - 1)
        return len(g.nodes) - 1

    skin_node = add_node(gl.Node(name=SKIN_NODE, mesh=0))

    # ---------------------------------------------------------------- rigid parts
    eyes, fixed, jaw_parts = _rigid_parts(model)
    part_nodes = {}
    for part, rough in [(p, 0.25) for p in eyes] + [(p, 0.4) for p in fixed + jaw_parts]:
        mat = colour_material(part.name, rough)
        local = (part.vertices - part.origin) * s
        g.meshes.append(
            gl.Mesh(
                name=part.name,
                primitives=[
                    gl.Primitive(
                        attributes=gl.Attributes(
                            POSITION=blob.accessor(local, "VEC3", target=_ARRAY, minmax=True),
                            NORMAL=blob.accessor(
                                part.normals / np.linalg.norm(part.normals, axis=1)[:, None],
                                "VEC3",
                                target=_ARRAY,
                            ),
                            COLOR_0=blob.accessor(part.colors, "VEC3", target=_ARRAY),
                        ),
                        indices=blob.accessor(
                            np.asarray(part.triangles).reshape(-1),
                            "SCALAR",
                            target=_ELEMENTS,
                            ints=True,
                        ),  # fmt: skip
                        material=mat,
                    )
                ],
            )
        )
        part_nodes[part.name] = add_node(
            gl.Node(
                name=part.name,
                mesh=len(g.meshes) - 1,
                translation=(part.origin * s).tolist() if np.any(part.origin) else None,
            )
        )

    # ---------------------------------------------------------------- the animation
    anim = gl.Animation(name=ANIMATION_NAME, samplers=[], channels=[])
    times = blob.accessor(clip.times, "SCALAR", minmax=True)

    def channel(nodes, path_, values, type_):
        out = blob.accessor(values, type_)
        anim.samplers.append(gl.AnimationSampler(input=times, output=out, interpolation="LINEAR"))
        for n in nodes:
            anim.channels.append(
                gl.AnimationChannel(
                    sampler=len(anim.samplers) - 1,
                    target=gl.AnimationChannelTarget(node=n, path=path_),
                )
            )

    if n_targets:
        channel([skin_node], "weights", np.asarray(morph.weights).reshape(-1), "SCALAR")
    eye_nodes = [part_nodes[p.name] for p in eyes]
    if eye_nodes:
        gaze = clip.gaze if clip.gaze is not None else np.zeros((clip.n_frames, 2))
        channel(eye_nodes, "rotation", _quats([gaze_rotation(gz) for gz in gaze]), "VEC4")
    jaw_nodes = [part_nodes[p.name] for p in jaw_parts]
    if jaw_nodes:
        channel(jaw_nodes, "rotation", _quats([r for r, _ in sim.jaw]), "VEC4")
        channel(jaw_nodes, "translation", np.array([t for _, t in sim.jaw]) * s, "VEC3")
    if clip.poses is not None:
        channel([0], "rotation", _quats([r for r, _ in clip.poses]), "VEC4")
        channel([0], "translation", np.array([t for _, t in clip.poses]) * s, "VEC3")
    g.animations.append(anim)
    g.scenes.append(gl.Scene(name="myoface", nodes=[0]))

    g.buffers.append(gl.Buffer(byteLength=len(blob.data)))
    g.set_binary_blob(bytes(blob.data))
    with atomic_output(path) as tmp:
        g.save_binary(str(tmp))
    return Path(path)


@dataclass(frozen=True, eq=False)
class GlbSkin:
    """The skin animation of an exported file, as a client evaluates it
    (:func:`read_glb_skin`): ``times`` (T,) s and the skin vertices ``skin`` (T, V, 3) m in
    the skin node's frame (the head frame) at each keyframe."""

    times: np.ndarray
    skin: np.ndarray
    names: list
    #: the bytes of the animation's keyframes (times and values of every sampler): what grows
    #: with the clip's length, where the meshes, targets and texture do not
    animation_bytes: int = 0


def _read(g, blob: bytes, index: int) -> np.ndarray:
    acc = g.accessors[index]
    bv = g.bufferViews[acc.bufferView]
    dtype = {_F32: np.float32, _U32: np.uint32, 5123: np.uint16}[acc.componentType]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type]
    start = (bv.byteOffset or 0) + (acc.byteOffset or 0)
    a = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
    return a.reshape(acc.count, width) if width > 1 else a


def read_glb_skin(path: str | os.PathLike) -> GlbSkin:
    """Read an exported file back and evaluate its skin at each keyframe of the weights'
    animation: base + sum of weight x target (what a glTF client shows at those times)."""
    gl = _pygltflib()
    try:
        g = gl.GLTF2().load_binary(str(path))
    except Exception as exc:  # pygltflib raises whatever its parser met
        raise MyofaceFormatError(f"{path}: not a binary glTF file ({exc})") from None
    blob = g.binary_blob()
    node = next((n for n in g.nodes if n.name == SKIN_NODE), None)
    if node is None or node.mesh is None:
        raise MyofaceFormatError(f"{path}: no '{SKIN_NODE}' node with a mesh")
    mesh = g.meshes[node.mesh]
    prim = mesh.primitives[0]
    base = _read(g, blob, prim.attributes.POSITION).astype(np.float64)
    targets = [_read(g, blob, t["POSITION"]).astype(np.float64) for t in (prim.targets or [])]
    names = list((mesh.extras or {}).get("targetNames", []))
    anim = next((a for a in g.animations if a.name == ANIMATION_NAME), None)
    if anim is None:
        raise MyofaceFormatError(f"{path}: no '{ANIMATION_NAME}' animation")
    seen = {i for a in g.animations for smp in a.samplers for i in (smp.input, smp.output)}
    anim_bytes = sum(g.bufferViews[g.accessors[i].bufferView].byteLength for i in seen)
    skin_index = g.nodes.index(node)
    ch = [c for c in anim.channels if c.target.node == skin_index and c.target.path == "weights"]
    if not ch:  # no morph target: the skin stays at rest
        smp = anim.samplers[anim.channels[0].sampler] if anim.channels else None
        times = _read(g, blob, smp.input).astype(np.float64) if smp else np.zeros(1)
        return GlbSkin(times, np.repeat(base[None], len(times), axis=0), names, anim_bytes)
    smp = anim.samplers[ch[0].sampler]
    times = _read(g, blob, smp.input).astype(np.float64)
    w = _read(g, blob, smp.output).astype(np.float64).reshape(len(times), len(targets))
    if not targets:
        raise MyofaceValueError(f"{path}: weights animated but no morph target")
    skin = base[None] + np.einsum("tk,kvc->tvc", w, np.array(targets))
    return GlbSkin(times, skin, names, anim_bytes)
