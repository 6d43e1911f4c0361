"""What the viewer draws, and how it follows the physics: the skin (plain or texture-mapped), the
dressing that makes the openings read as eyes and a mouth, the muscle vectors, the tissue
lattice's spring layers and the bone nodes.

Everything is built once; :meth:`FaceScene.update` moves what is visible to a new tissue state.
The scene is in metres (viser's unit); the model is in millimetres.
"""

from __future__ import annotations

import io
import json
import struct

import numpy as np

from myoface.render.raster import vertex_normals_numba
from myoface.render.renderer import to_srgb8
from myoface.render.wrinkles import WrinkleNormalMap
from myoface.synth import muscle_segments

MM = 1e-3
SKIN_RGB = (226, 178, 154)
#: spring layers of the lattice (``TissueModel.spring_material``), names and colours
SPRING_LAYERS = (
    ("epidermis", (240, 240, 240)),
    ("dermis", (230, 120, 110)),
    ("fat", (240, 200, 60)),
    ("muscle layer", (200, 60, 60)),
)
BONE_RGB = (90, 140, 255)
MUSCLE_RGB = (255, 200, 40)
#: the textured skin's bounds in the GLB are the rest bounds widened by this (m), so the
#: client's culling never clips a deformed face
GLB_BOUNDS_PAD_M = 0.04


def _srgb8(linear) -> tuple[int, int, int]:
    c = to_srgb8(np.asarray(linear, dtype=np.float64).reshape(1, 1, 3))[0, 0]
    return tuple(int(x) for x in c)


def _quaternion_wxyz(rot: np.ndarray) -> tuple[float, float, float, float]:
    """The unit quaternion (w, x, y, z) of a rotation matrix (3, 3) (Shepperd's method)."""
    tr = np.trace(rot)
    if tr > 0:
        s = 2.0 * np.sqrt(1.0 + tr)
        q = (0.25 * s, (rot[2, 1] - rot[1, 2]) / s, (rot[0, 2] - rot[2, 0]) / s,
             (rot[1, 0] - rot[0, 1]) / s)  # fmt: skip
    else:
        i = int(np.argmax(np.diag(rot)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + rot[i, i] - rot[j, j] - rot[k, k])
        v = np.zeros(3)
        v[i] = 0.25 * s
        v[j] = (rot[j, i] + rot[i, j]) / s
        v[k] = (rot[k, i] + rot[i, k]) / s
        q = ((rot[k, j] - rot[j, k]) / s, *v)
    return tuple(float(c) for c in q)


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    out = np.zeros_like(vertices, dtype=np.float64)
    vertex_normals_numba(
        np.ascontiguousarray(vertices, dtype=np.float64),
        np.ascontiguousarray(triangles, dtype=np.int64),
        out,
    )
    return out


class TexturedSkinGLB:
    """A binary glTF of the texture-mapped skin whose vertex positions and normals can be
    replaced in place: the texture is encoded once, each update only rewrites two arrays.

    Parameters
    ----------
    vertices : (V, 3) mm — rest positions (for the bounds).
    triangles : (T, 3) int
    uv : (V, 2) texture coordinates
    texture : (H, W, 3) linear RGB in [0, 1] or sRGB uint8
    wrinkles : a :class:`~myoface.render.wrinkles.WrinkleNormalMap` of the face, or None: its
        normal map (the skin's furrows where it is compressed) goes into the GLB's material
        with each new skin, so the browser shades the same folds as the CPU renderer.
    """

    def __init__(self, vertices, triangles, uv, texture, wrinkles=None):
        import trimesh
        from PIL import Image

        tex = texture if texture.dtype == np.uint8 else to_srgb8(texture)
        self.wrinkles = wrinkles
        flat = np.full((4, 4, 3), (128, 128, 255), np.uint8)
        material = trimesh.visual.material.PBRMaterial(
            baseColorTexture=Image.fromarray(tex),
            normalTexture=Image.fromarray(flat) if wrinkles is not None else None,
            metallicFactor=0.0,
            roughnessFactor=0.65,
            doubleSided=True,
        )
        v = np.asarray(vertices, dtype=np.float64)
        mesh = trimesh.Trimesh(
            v * MM,
            np.asarray(triangles),
            visual=trimesh.visual.TextureVisuals(uv=np.asarray(uv), material=material),
            process=False,
        )
        glb = mesh.export(file_type="glb", include_normals=True)
        (json_len,) = struct.unpack_from("<I", glb, 12)
        doc = json.loads(glb[20 : 20 + json_len])
        binary = bytes(glb[20 + json_len + 8 :])
        prim = doc["meshes"][0]["primitives"][0]["attributes"]
        # the binary chunk as one piece per buffer view, re-assembled on each call (the normal
        # map's PNG changes length from frame to frame)
        self._views = [
            bytearray(binary[bv.get("byteOffset", 0) : bv.get("byteOffset", 0) + bv["byteLength"]])
            for bv in doc["bufferViews"]
        ]
        self._at = {}
        for key in ("POSITION", "NORMAL"):
            acc = doc["accessors"][prim[key]]
            if acc["count"] != len(v) or acc["componentType"] != 5126:
                raise RuntimeError("unexpected glTF layout from trimesh")  # pragma: no cover
            self._at[key] = (acc["bufferView"], acc.get("byteOffset", 0))
        self._normal_view = None
        if wrinkles is not None:
            mat = doc["materials"][doc["meshes"][0]["primitives"][0]["material"]]
            image = doc["textures"][mat["normalTexture"]["index"]]["source"]
            self._normal_view = doc["images"][image]["bufferView"]
        self._flat_png = self._views[self._normal_view] if wrinkles is not None else None
        pos = doc["accessors"][prim["POSITION"]]
        pos["min"] = (v.min(axis=0) * MM - GLB_BOUNDS_PAD_M).tolist()
        pos["max"] = (v.max(axis=0) * MM + GLB_BOUNDS_PAD_M).tolist()
        self._doc = doc
        self.triangles = np.asarray(triangles)
        self.n = len(v)
        #: whether the last :meth:`data` carried a non-flat normal map
        self.wrinkled = False

    def data(self, vertices) -> bytes:
        """The GLB with the skin at ``vertices`` (V, 3) mm (and its wrinkles' normal map)."""
        v = np.asarray(vertices, dtype=np.float64)
        n = vertex_normals(v, self.triangles)
        for key, arr in (("POSITION", v * MM), ("NORMAL", n)):
            a = np.ascontiguousarray(arr, dtype="<f4").tobytes()
            view, o = self._at[key]
            self._views[view][o : o + len(a)] = a
        if self.wrinkles is not None:
            img = self.wrinkles.image(v)
            self.wrinkled = img is not None
            self._views[self._normal_view] = self._flat_png if img is None else _png(img)
        doc = self._doc
        parts, offset = [], 0
        for bv, chunk in zip(doc["bufferViews"], self._views, strict=True):
            bv["byteOffset"], bv["byteLength"] = offset, len(chunk)
            pad = -len(chunk) % 4
            parts += [chunk, b"\0" * pad]
            offset += len(chunk) + pad
        doc["buffers"][0]["byteLength"] = offset
        header = json.dumps(doc, separators=(",", ":")).encode()
        header += b" " * (-len(header) % 4)
        out = io.BytesIO()
        out.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(header) + 8 + offset))
        out.write(struct.pack("<I4s", len(header), b"JSON") + header)
        out.write(struct.pack("<I4s", offset, b"BIN\x00"))
        for part in parts:
            out.write(part)
        return out.getvalue()


def _png(img: np.ndarray) -> bytes:
    """``img`` (H, W, 3) uint8 as PNG bytes (fast compression: it is sent once per update)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def read_glb_positions(glb: bytes) -> np.ndarray:
    """The POSITION array (V, 3) of the first primitive of a GLB (for tests and checks)."""
    (json_len,) = struct.unpack_from("<I", glb, 12)
    doc = json.loads(glb[20 : 20 + json_len])
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    o = 20 + json_len + 8 + view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(glb, "<f4", acc["count"] * 3, o).reshape(-1, 3).astype(np.float64)


class FaceScene:
    """The viewer's 3-D scene for one model, on a viser ``SceneApi``.

    ``renderer`` provides the dressing (eye sockets, mouth cavity, eyeballs) and the skin
    texture, so the web view and the rendered images show the same face.
    """

    def __init__(self, scene_api, model, renderer):
        self.api = scene_api
        self.model = model
        self.renderer = renderer
        sc = renderer.scene
        face = model.face
        skin = model.skin_vertices()
        #: the tissue node positions (N, 3) mm shown now (the last :meth:`update`)
        self.x = model.rest_state().x
        self.skin = scene_api.add_mesh_simple(
            "/face/skin",
            (skin * MM).astype(np.float32),
            face.triangles.astype(np.int32),
            color=SKIN_RGB,
            side="double",
        )
        self.textured = None
        self._glb = None
        if renderer.texture is not None and face.uv is not None:
            wrinkles = None
            if renderer.wrinkles is not None:
                wrinkles = WrinkleNormalMap(renderer.wrinkles, face.uv)
            self._glb = TexturedSkinGLB(
                face.vertices, face.triangles, face.uv, renderer.texture, wrinkles
            )
            self.textured = scene_api.add_glb(
                "/face/skin_textured", self._glb.data(skin), visible=False
            )
        # dressing: one fan per opening (follows the skin), the eyeballs (fixed in the head)
        pos = renderer.positions(skin)
        self.fans = []
        start = len(face.triangles)
        for k, (loop, first, center, _depth) in enumerate(sc.fans):
            tris = sc.tris[start : start + len(loop)] - first
            start += len(loop)
            handle = scene_api.add_mesh_simple(
                f"/face/dressing/opening_{k}",
                (pos[first : center + 1] * MM).astype(np.float32),
                tris.astype(np.int32),
                color=_srgb8(sc.vcol[first]),
                side="double",
            )
            self.fans.append((handle, first, center))
        # the mouth's cavity (follows the lips' margin; one colour, the dark of its middle)
        self.cavity = None
        if sc.cavity is not None:
            loop, first = sc.cavity
            n_cav = 2 * len(loop) + 1
            tris = sc.tris[(sc.tris.min(axis=1) >= first) & (sc.tris.max(axis=1) < first + n_cav)]
            self.cavity = scene_api.add_mesh_simple(
                "/face/dressing/mouth_cavity",
                (pos[first : first + n_cav] * MM).astype(np.float32),
                (tris - first).astype(np.int32),
                color=_srgb8(sc.vcol[first + len(loop)]),
                side="double",
            )
        # fixed in the head: the eyeballs (each turned about its centre by the gaze,
        # :meth:`set_gaze`) and the upper teeth; carried by the jaw: lower teeth, tongue
        self.eyes = []
        end = sc.n_dynamic
        for k, (a, b, centre) in enumerate(renderer._eyeballs):
            eye = self._static_mesh(f"/face/dressing/eye_{k}", pos, a, b, origin=centre)
            if eye is not None:
                self.eyes.append(eye)
            end = max(end, b)
        self.upper_teeth = self._static_mesh("/face/dressing/upper_teeth", pos, end, sc.n_jaw_first)
        self.jaw = self._static_mesh("/face/dressing/jaw", pos, sc.n_jaw_first, len(pos))
        #: the eyes' gaze shown, ``(yaw, pitch)`` rad (None: straight ahead)
        self.gaze = None
        ins, org = muscle_segments(model)
        self.vectors = scene_api.add_line_segments(
            "/muscles",
            (np.stack([ins, org], axis=1) * MM).astype(np.float32),
            colors=MUSCLE_RGB,
            thickness=2.0,
            thickness_units="screen",
            visible=False,
        )
        t = model.tissue
        x = self.x
        self.layers = {}
        for m, (name, rgb) in enumerate(SPRING_LAYERS):
            sel = np.flatnonzero(t.spring_material == m)
            if len(sel) == 0:
                continue
            handle = scene_api.add_line_segments(
                f"/lattice/{name.replace(' ', '_')}",
                self._segments(x, sel),
                colors=rgb,
                thickness=1.0,
                thickness_units="screen",
                visible=False,
            )
            self.layers[name] = (handle, sel)
        self.bone_index = np.flatnonzero(t.kinematic)
        self.bones = scene_api.add_point_cloud(
            "/lattice/bone_nodes",
            (x[self.bone_index] * MM).astype(np.float32),
            colors=BONE_RGB,
            point_size=0.0018,
            point_shape="circle",
            precision="float32",
            visible=False,
        )

    def _static_mesh(self, name, pos, lo, hi, origin=None):
        """A vertex-coloured mesh of the scene's rigid vertices lo..hi-1 (None when empty);
        ``origin`` (3,) mm: its vertices relative to that point, the handle placed there (so
        that a rotation of the handle turns the mesh about it)."""
        sc = self.renderer.scene
        tris = sc.tris[(sc.tris.min(axis=1) >= lo) & (sc.tris.max(axis=1) < hi)] - lo
        if hi <= lo or not len(tris):
            return None
        import trimesh

        col = to_srgb8(sc.vcol[lo:hi].reshape(1, -1, 3))[0]
        o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
        mesh = trimesh.Trimesh(
            (pos[lo:hi] - o) * MM,
            tris,
            vertex_colors=np.column_stack([col, np.full(len(col), 255, np.uint8)]),
            process=False,
        )
        return self.api.add_mesh_trimesh(name, mesh, position=tuple(float(c) for c in o * MM))

    def _segments(self, x, sel) -> np.ndarray:
        t = self.model.tissue
        return (np.stack([x[t.spring_i[sel]], x[t.spring_j[sel]]], axis=1) * MM).astype(np.float32)

    # ------------------------------------------------------------------ visibility
    @property
    def textured_on(self) -> bool:
        return self.textured is not None and self.textured.visible

    def set_textured(self, on: bool) -> None:
        """Show the texture-mapped skin (when the face has a texture) or the plain one."""
        if self.textured is None:
            return
        skin = self.x[: self.model.face.n_vertices]
        if on:
            self.textured.glb_data = self._glb.data(skin)
        else:
            self.skin.vertices = (skin * MM).astype(np.float32)
        self.textured.visible = bool(on)
        self.skin.visible = not on

    def set_layer(self, name: str, on: bool) -> None:
        handle, sel = self.layers[name]
        if on:
            handle.points = self._segments(self.x, sel)
        handle.visible = bool(on)

    def set_bones(self, on: bool) -> None:
        if on:
            self.bones.points = (self.x[self.bone_index] * MM).astype(np.float32)
        self.bones.visible = bool(on)

    # ------------------------------------------------------------------ updates
    def set_gaze(self, gaze=None) -> None:
        """Turn both eyeballs about their centres to ``gaze`` ``(yaw_rad, pitch_rad)`` (as the
        renderer's ``gaze=``: yaw towards the subject's left, pitch up), or straight ahead."""
        from myoface.render.renderer import gaze_rotation

        rot = np.eye(3) if gaze is None else gaze_rotation(gaze)
        self.gaze = None if gaze is None else tuple(float(g) for g in gaze)
        for eye in self.eyes:
            eye.wxyz = _quaternion_wxyz(rot)

    def update(self, x: np.ndarray, jaw=None) -> None:
        """Move everything visible to the tissue node positions ``x`` (N, 3) mm and the
        mandible's rigid motion ``jaw`` (:meth:`myoface.model.FaceModel.jaw_pose`; None:
        closed)."""
        self.x = x
        skin = x[: self.model.face.n_vertices]
        if self.textured_on:
            self.textured.glb_data = self._glb.data(skin)
        else:
            self.skin.vertices = (skin * MM).astype(np.float32)
        if self.fans or self.cavity is not None:
            pos = self.renderer.positions(skin)
            for handle, first, center in self.fans:
                handle.vertices = (pos[first : center + 1] * MM).astype(np.float32)
            if self.cavity is not None:
                loop, first = self.renderer.scene.cavity
                n_cav = 2 * len(loop) + 1
                self.cavity.vertices = (pos[first : first + n_cav] * MM).astype(np.float32)
        if self.jaw is not None:
            rot, shift = (np.eye(3), np.zeros(3)) if jaw is None else jaw
            self.jaw.wxyz = _quaternion_wxyz(np.asarray(rot, dtype=np.float64))
            self.jaw.position = tuple(float(c) for c in np.asarray(shift) * MM)
        for handle, sel in self.layers.values():
            if handle.visible:
                handle.points = self._segments(x, sel)
        if self.bones.visible:
            self.bones.points = (x[self.bone_index] * MM).astype(np.float32)
