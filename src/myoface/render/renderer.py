"""Rendering a face (or any triangle mesh) to an RGB image on the CPU.

>>> from myoface.face import load_default_face
>>> from myoface.render import Camera, Renderer
>>> face = load_default_face()
>>> r = Renderer(face, Camera.front(face.vertices, width=512, height=512))
>>> image = r.render()                   # (512, 512, 3) uint8; r.render(new_vertices) re-renders
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numba
import numpy as np

from myoface.errors import MyofaceValueError
from myoface.face import FaceMesh
from myoface.face.eyes import eyeball_center
from myoface.face.teeth import fit_dentition
from myoface.render import dressing, mouth
from myoface.render.camera import Camera
from myoface.render.raster import (
    SETUP_COLS,
    W_COLS,
    attribute_planes,
    planes_columns,
    setup_triangles,
    shade_resolve,
    srgb_lut,
    vertex_normals_numba,
    visibility,
)
from myoface.render.wrinkles import WrinkleField, wrinkle_planes

_SRGB_LUT = srgb_lut()
_NO_U8 = np.zeros((1, 1, 3), np.uint8)  # placeholders for the output shade_resolve does not use
_NO_F32 = np.zeros((1, 1, 3), np.float32)
_NO_FLAG = np.zeros(0, bool)  # no wrinkled triangle: the shader skips its test

BACKGROUND_TOP = (0.050, 0.055, 0.065)  # linear RGB, a soft studio gradient
BACKGROUND_BOTTOM = (0.012, 0.013, 0.016)


@dataclass(frozen=True)
class Light:
    """A directional light: ``direction`` points from the scene towards the light (world)."""

    direction: tuple
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0


def default_lights() -> list[Light]:
    """Key (upper left of the image, warm), fill (right, cool), rim (behind, above)."""
    return [
        Light((-0.55, 0.55, 0.75), (1.0, 0.95, 0.88), 0.95),
        Light((0.75, 0.05, 0.6), (0.85, 0.9, 1.0), 0.35),
        Light((0.0, 0.6, -0.8), (1.0, 1.0, 1.0), 0.25),
    ]


@dataclass(frozen=True)
class SkinMaterial:
    """Skin reflectance: ``albedo`` (linear RGB, multiplies the texture), ambient light,
    Blinn-Phong specular strength and shininess (skin is a fairly rough dielectric)."""

    albedo: tuple = (1.0, 1.0, 1.0)
    ambient: tuple = (0.16, 0.15, 0.15)
    specular: float = 0.10
    shininess: float = 22.0


def _check_vertices(v, n: int, what: str = "vertices") -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (n, 3):
        raise MyofaceValueError(f"{what} must have shape ({n}, 3); got {a.shape}")
    if not np.isfinite(a).all():
        raise MyofaceValueError(f"{what} contain NaN or Inf")
    return np.ascontiguousarray(a)


def _rgb01(t: np.ndarray, what: str = "a texture") -> np.ndarray:
    """An image as float (H, W, 3) sRGB in [0, 1]: grey (H, W) or (H, W, 1), grey + alpha,
    RGB or RGBA; integers scaled by their type's range (8 or 16 bits), floats as they are."""
    if t.ndim == 2:
        t = t[:, :, None]
    if t.ndim != 3 or t.shape[2] not in (1, 2, 3, 4) or t.shape[0] < 1 or t.shape[1] < 1:
        raise MyofaceValueError(
            f"{what} must be an (H, W) grey or (H, W, 3) colour image; got shape {t.shape}"
        )
    t = t[:, :, :1] if t.shape[2] <= 2 else t[:, :, :3]  # drop the alpha channel
    if t.dtype == np.bool_:
        t = t.astype(np.float64)
    elif np.issubdtype(t.dtype, np.integer):
        t = t.astype(np.float64) / float(np.iinfo(t.dtype).max)
    elif np.issubdtype(t.dtype, np.floating):
        t = t.astype(np.float64)
    else:
        raise MyofaceValueError(f"{what} must hold numbers; got {t.dtype}")
    if not np.isfinite(t).all():
        raise MyofaceValueError(f"{what} must hold finite values")
    return np.repeat(t, 3, axis=2) if t.shape[2] == 1 else t


def _check_pose(pose, what: str = "pose") -> tuple[np.ndarray, np.ndarray]:
    """``(rotation (3, 3), translation (3,))`` as float arrays, checked."""
    try:
        rot, shift = (np.asarray(a, dtype=np.float64) for a in pose)
    except (TypeError, ValueError):
        raise MyofaceValueError(f"{what} must be (rotation (3, 3), translation (3,) mm)") from None
    if rot.shape != (3, 3) or shift.shape != (3,) or not np.isfinite(rot).all():
        raise MyofaceValueError(
            f"{what} must be (rotation (3, 3), translation (3,) mm); got shapes {rot.shape}, "
            f"{shift.shape}"
        )
    if not np.isfinite(shift).all() or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6):
        raise MyofaceValueError(f"{what} must be a finite rotation matrix and translation")
    return rot, shift


def _srgb_to_linear(t: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] -> linear light (IEC 61966-2-1)."""
    return np.where(t <= 0.04045, t / 12.92, ((t + 0.055) / 1.055) ** 2.4)


#: the linear light (float32) of each 8-bit sRGB code: an 8-bit texture is converted by lookup,
#: without the float64 copies of the formula (the same values)
_SRGB8_TO_LINEAR = _srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


def load_texture(texture) -> np.ndarray:
    """A texture as float32 linear RGB (H, W, 3) from an image array or a path: grey or colour,
    with or without alpha, 8 or 16 bits per channel (or floats in [0, 1]). A file is read by
    :func:`~myoface.face.image.read_image` (any colour space: CMYK, palette, grey, ... as
    RGB)."""
    if isinstance(texture, str | os.PathLike):
        from myoface.face.image import read_image

        texture = read_image(texture, "texture image")
    a = np.asarray(texture)
    if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] in (3, 4) and a.size:
        return np.ascontiguousarray(_SRGB8_TO_LINEAR[a[:, :, :3]])
    t = np.clip(_rgb01(a), 0, 1)
    return np.ascontiguousarray(_srgb_to_linear(t), dtype=np.float32)


def to_srgb8(linear: np.ndarray) -> np.ndarray:
    c = np.clip(linear, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return (s * 255.0 + 0.5).astype(np.uint8)


@dataclass
class _Scene:
    """Packed static arrays of everything drawn: mesh + dressing."""

    tris: np.ndarray
    tri_tex: np.ndarray
    tri_cull: np.ndarray  # back-face culled (the closed eyeballs)
    uv: np.ndarray
    vcol: np.ndarray
    n_face: int
    normals_static: np.ndarray  # (N, 3) for the static part (eyeballs)
    fans: list = field(default_factory=list)  # (loop, first copy index, center index, depth)
    n_dynamic: int = 0  # face vertices + fan vertices (normals computed per frame)
    dyn_tris: np.ndarray | None = None
    #: the mouth cavity behind the teeth: (lip margin loop, first vertex), or None
    cavity: tuple | None = None
    #: vertices from this index on (lower teeth, tongue) follow the jaw
    n_jaw_first: int = 0


#: the largest gaze angle (rad) :func:`gaze_rotation` takes, horizontally and vertically: the
#: eyes' range of motion is about 45 degrees from straight ahead (Guitton & Volle, "Gaze
#: control in humans: eye-head coordination during orienting movements to targets within and
#: beyond the oculomotor range", J. Neurophysiol. 58, 1987)
MAX_GAZE_RAD = np.deg2rad(45.0)


def gaze_rotation(gaze) -> np.ndarray:
    """The rotation (3, 3) of an eyeball for ``gaze = (yaw_rad, pitch_rad)``: straight ahead
    (+z) turns to ``(sin(yaw) cos(pitch), sin(pitch), cos(yaw) cos(pitch))`` (yaw towards the
    subject's left, +x; pitch up), each angle within :data:`MAX_GAZE_RAD`."""
    try:
        yaw, pitch = (float(a) for a in gaze)
    except (TypeError, ValueError):
        raise MyofaceValueError(f"gaze must be (yaw_rad, pitch_rad); got {gaze!r}") from None
    for name, a in (("yaw", yaw), ("pitch", pitch)):
        if not np.isfinite(a) or abs(a) > MAX_GAZE_RAD:
            raise MyofaceValueError(
                f"gaze {name} must be finite and within +-{MAX_GAZE_RAD:.3f} rad (45 degrees); "
                f"got {a}"
            )
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    ry = np.array([[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, sp], [0.0, -sp, cp]])
    return ry @ rx


class Renderer:
    """Renders a :class:`~myoface.face.FaceMesh` (rest or deformed) with a camera and lights.

    Everything static (topology, texture, dressing) is prepared once; :meth:`render` takes new
    skin vertex positions (V, 3) mm each frame.

    Parameters
    ----------
    face : FaceMesh
    camera : Camera
    lights : list of Light (default :func:`default_lights`)
    material : SkinMaterial
    texture : image array, path, or None — overrides ``face.texture``; when both are absent a
        face with the default landmarks gets :func:`dressing.default_skin_texture`.
    ssaa : int — supersampling factor per axis (anti-aliasing; 1 = off).
    dress : bool — add eyeballs, sockets and the mouth cavity (faces with eye/mouth landmarks).
    teeth : bool — with ``dress``, teeth, gums, tongue and a shaded cavity in the mouth of a
        face with the lip landmark groups (:func:`myoface.face.teeth.fit_dentition`); else a
        dark fan closes the mouth.
    wrinkles : bool — shade furrows where the skin is compressed (:mod:`.wrinkles`).
    """

    def __init__(
        self,
        face,
        camera: Camera,
        lights: list[Light] | None = None,
        material: SkinMaterial | None = None,
        texture=None,
        ssaa: int = 2,
        dress: bool = True,
        teeth: bool = True,
        wrinkles: bool = True,
    ):
        if not isinstance(ssaa, int | np.integer) or not 1 <= ssaa <= 4:
            raise MyofaceValueError(f"ssaa must be an integer in 1..4; got {ssaa!r}")
        self.face = face
        self.camera = camera
        self.lights = list(default_lights() if lights is None else lights)
        self.material = material or SkinMaterial()
        self.ssaa = int(ssaa)
        if texture is not None:
            self.texture = load_texture(texture)
        elif face.texture is not None:
            self.texture = load_texture(face.texture)
        elif face.uv is not None and "lip_upper_outer" in face.landmarks:
            self.texture = dressing.default_skin_texture(face)
        else:
            self.texture = None
        self.dentition = fit_dentition(face) if dress and teeth else None
        self.scene = self._build_scene(dress)
        self._big = camera.with_size(camera.width * self.ssaa, camera.height * self.ssaa)
        h, w = self._big.height, self._big.width
        # supersampled buffers, valid inside the last frame's drawn box only
        self._zbuf = np.empty((h, w), np.float32)
        self._tid = np.empty((h, w), np.int32)
        n_tris = len(self.scene.tris)
        self._setup = np.zeros((n_tris, SETUP_COLS))
        self._planes = np.zeros((n_tris, planes_columns(len(self.lights))))
        self._tbox = np.zeros((n_tris, 4), np.int64)
        self._bbox = np.array([w, -1, h, -1], np.int64)
        rows = np.linspace(0, 1, h)[:, None]
        top, bot = np.array(BACKGROUND_TOP), np.array(BACKGROUND_BOTTOM)
        self._background = np.ascontiguousarray(top * (1 - rows) + bot * rows)
        self._light_dir = np.array(
            [np.asarray(li.direction, float) / np.linalg.norm(li.direction) for li in self.lights]
        ).reshape(-1, 3)
        self._light_col = np.array(
            [np.asarray(li.color, float) * li.intensity for li in self.lights]
        ).reshape(-1, 3)
        nf = face.n_triangles
        self.wrinkles = WrinkleField(face) if wrinkles and nf > 0 else None
        self._wplanes = np.zeros((nf if self.wrinkles else 0, W_COLS))
        self._wflag = np.zeros(nf if self.wrinkles else 0, bool)
        self._face_tris = np.ascontiguousarray(face.triangles, dtype=np.int64)
        self._wrinkled = False  # the last frame has a wrinkled triangle
        self._spec = np.ones(n_tris)
        if self.scene.cavity is not None:  # the inside of the mouth is wet but in shadow
            k = len(self.scene.cavity[0])
            first_cavity = len(self.scene.dyn_tris) - 3 * k
            self._spec[first_cavity : len(self.scene.dyn_tris)] = 0.0

    # ------------------------------------------------------------------ scene
    def _build_scene(self, dress: bool) -> _Scene:
        f = self.face
        nv = f.n_vertices
        tris = [f.triangles]
        has_tex = self.texture is not None and f.uv is not None
        tri_tex = [np.full(len(f.triangles), has_tex)]
        tri_cull = [np.zeros(len(f.triangles), bool)]
        uv = [f.uv if f.uv is not None else np.zeros((nv, 2))]
        vcol = [np.tile(np.asarray(self.material.albedo, float), (nv, 1))]
        fans = []
        n = nv
        openings = dressing.find_openings(f) if dress else []
        cavity_op = None
        for op in openings:
            k = len(op.loop)
            if op.name == "mouth" and self.dentition is not None:
                cavity_op = op  # drawn below, after the fans
                continue
            first, center = n, n + k
            ring = np.arange(k)
            fan = np.column_stack([first + ring, first + (ring + 1) % k, np.full(k, center)])
            pts = f.vertices[op.loop]
            c = pts.mean(axis=0) - np.array([0, 0, op.depth_mm])
            if not dressing.orient_fan(pts, c):
                fan = fan[:, ::-1]
            tris.append(fan)
            tri_tex.append(np.zeros(k, bool))
            tri_cull.append(np.zeros(k, bool))
            uv.append(np.zeros((k + 1, 2)))
            vcol.append(op.vertex_colors(f.vertices))
            fans.append((op.loop, first, center, op.depth_mm))
            n += k + 1
        cavity = None
        if cavity_op is not None:
            k = len(cavity_op.loop)
            tris.append(mouth.cavity_triangles(k, n))
            tri_tex.append(np.zeros(3 * k, bool))
            tri_cull.append(np.zeros(3 * k, bool))
            uv.append(np.zeros((2 * k + 1, 2)))
            vcol.append(mouth.cavity_colors(k))
            cavity = (cavity_op.loop, n)
            n += 2 * k + 1
        n_dynamic = n
        dyn_tris = np.concatenate(tris).astype(np.int64)
        static_normals = []
        static_pos = []

        #: (first vertex, end, centre) of each eyeball, for the gaze
        def add_static(v, t, nrm, col) -> int:
            """Append a closed, untextured mesh fixed in the head (back faces culled); the
            index of its first vertex."""
            nonlocal n
            first = n
            tris.append(t + first)
            tri_tex.append(np.zeros(len(t), bool))
            tri_cull.append(np.ones(len(t), bool))
            uv.append(np.zeros((len(v), 2)))
            vcol.append(col)
            static_pos.append(v)
            static_normals.append(nrm)
            n += len(v)
            return first

        self._eyeballs = []
        #: each eyeball's side ("l", "r"; the opening's name's last letter), in
        #: ``_eyeballs``' order, for a gaze given per eye
        self._eye_sides = []
        for op in openings:
            if not op.name.startswith("eye"):
                continue
            center = eyeball_center(f.vertices, op.loop)  # where the eyelids slide
            v, t, nrm, col = dressing.eyeball(center, np.array([0, 0, 1.0]), dressing.EYE_RADIUS_MM)
            first = add_static(v, t, nrm, col)
            self._eyeballs.append((first, first + len(v), center))
            self._eye_sides.append(op.name[-1])
        jaw_first = n
        self._teeth_tri0 = sum(len(t) for t in tris)
        if cavity is not None:
            meshes = mouth.mouth_meshes(self.dentition)
            add_static(*meshes.upper)
            jaw_first = add_static(*meshes.lower)
        scene = _Scene(
            np.ascontiguousarray(np.concatenate(tris), dtype=np.int64),
            np.concatenate(tri_tex),
            np.concatenate(tri_cull),
            np.ascontiguousarray(np.concatenate(uv), dtype=np.float64),
            np.ascontiguousarray(np.concatenate(vcol), dtype=np.float64),
            nv,
            np.concatenate(static_normals) if static_normals else np.zeros((0, 3)),
            fans,
            n_dynamic,
            dyn_tris,
            cavity,
            jaw_first,
        )
        self._static_pos = np.concatenate(static_pos) if static_pos else np.zeros((0, 3))
        self._n_total = n
        return scene

    def positions(self, skin: np.ndarray, jaw=None, gaze=None) -> np.ndarray:
        """Positions (N, 3) mm of every drawn vertex (skin, dressing fans, eyeballs, teeth) for
        the skin vertices ``skin``, the jaw's rigid motion ``jaw`` and the eyes' ``gaze`` (see
        :meth:`render`), in the order of :attr:`scene`."""
        sc = self.scene
        pos = np.empty((self._n_total, 3))
        pos[: sc.n_face] = skin
        for loop, first, center, depth in sc.fans:
            pts = skin[loop]
            pos[first : first + len(loop)] = pts
            pos[center] = pts.mean(axis=0) - np.array([0.0, 0.0, depth])
        if sc.cavity is not None:
            loop, first = sc.cavity
            mouth.cavity_positions(skin[loop], pos[first : first + 2 * len(loop) + 1])
        pos[sc.n_dynamic :] = self._static_pos
        if gaze is not None:
            for (a, b, c), g in zip(self._eyeballs, self._eye_rotations(gaze), strict=True):
                pos[a:b] = (pos[a:b] - c) @ g.T + c
        if jaw is not None:
            rot, shift = _check_pose(jaw, "jaw")
            pos[sc.n_jaw_first :] = pos[sc.n_jaw_first :] @ rot.T + shift
        return pos

    # ------------------------------------------------------------------ render
    def _eye_rotations(self, gaze) -> list[np.ndarray]:
        """Each eyeball's rotation (``_eyeballs``' order) for ``gaze``: ``(yaw_rad,
        pitch_rad)`` for both, or ``{"l": (yaw_rad, pitch_rad), "r": ...}`` per eye (the
        subject's left and right; an eye not given looks straight ahead)."""
        if isinstance(gaze, dict):
            unknown = set(gaze) - {"l", "r"}
            if unknown:
                raise MyofaceValueError(
                    f"a gaze per eye is {{'l': (yaw, pitch), 'r': (yaw, pitch)}}; got keys "
                    f"{sorted(map(str, unknown))}"
                )
            return [gaze_rotation(gaze.get(side, (0.0, 0.0))) for side in self._eye_sides]
        g = gaze_rotation(gaze)
        return [g] * len(self._eyeballs)

    def render_linear(self, vertices=None, pose=None, jaw=None, gaze=None) -> np.ndarray:
        """The image (H, W, 3) float32 in linear RGB (before tone mapping); ``pose``, ``jaw``
        and ``gaze`` as for :meth:`render`."""
        out = np.empty((self.camera.height, self.camera.width, 3), np.float32)
        self._draw(vertices, None, out, pose, jaw, gaze)
        return out

    def render(self, vertices=None, pose=None, jaw=None, gaze=None) -> np.ndarray:
        """The image (H, W, 3) uint8 sRGB of the skin at ``vertices`` (default: rest).

        ``pose``: None, or ``(rotation (3, 3), translation (3,) mm)``, a rigid motion of the
        whole head (skin, eyes, mouth), ``x -> rotation @ x + translation``, before the camera
        sees it; the lights stay where they are (a head that turns in a lit room).
        ``jaw``: None (closed), or the mandible's rigid motion from rest in the head frame, the
        same form (:meth:`myoface.model.FaceModel.jaw_pose`): the lower teeth and the tongue
        follow it.
        ``gaze``: None (straight ahead), or ``(yaw_rad, pitch_rad)``: both eyeballs turned about
        their centres, yaw towards the subject's left (+x), pitch up (:func:`gaze_rotation`);
        or ``{"l": (yaw_rad, pitch_rad), "r": (yaw_rad, pitch_rad)}``, each eye its own (eyes
        that converge on a near point, e.g. the camera)."""
        out = np.empty((self.camera.height, self.camera.width, 3), np.uint8)
        self._draw(vertices, out, None, pose, jaw, gaze)
        return out

    def _draw(self, vertices, out8, outf, pose=None, jaw=None, gaze=None) -> None:
        skin = (
            self.face.vertices
            if vertices is None
            else _check_vertices(vertices, self.face.n_vertices)
        )
        sc = self.scene
        pos = self.positions(skin, jaw, gaze)
        rot = None
        if pose is not None:
            rot, shift = _check_pose(pose)
            pos = pos @ rot.T + shift
        normals = np.empty_like(pos)
        vertex_normals_numba(pos[: sc.n_dynamic], sc.dyn_tris, normals[: sc.n_dynamic])
        normals[sc.n_dynamic :] = sc.normals_static
        if gaze is not None:
            for (a, b, _), g in zip(self._eyeballs, self._eye_rotations(gaze), strict=True):
                normals[a:b] = normals[a:b] @ g.T
        if jaw is not None:
            jrot = np.asarray(jaw[0], dtype=np.float64)
            normals[sc.n_jaw_first :] = normals[sc.n_jaw_first :] @ jrot.T
        if rot is not None:
            normals[sc.n_dynamic :] = normals[sc.n_dynamic :] @ rot.T
        cam = self._big
        scr = cam.project(pos)
        winv = np.ones(len(pos)) if cam.orthographic else 1.0 / np.maximum(scr[:, 2], 1e-9)
        setup_triangles(
            scr, winv, sc.tris, sc.tri_cull, cam.orthographic, cam.width, cam.height, self.ssaa,
            self._setup, self._tbox, self._bbox,
        )  # fmt: skip
        if sc.cavity is not None:
            self._clip_to_mouth(scr)
        nt = numba.get_num_threads()
        self._wrinkle_planes(skin, pos[: sc.n_face], winv)
        visibility(self._setup, self._tbox, self._bbox, self._zbuf, self._tid, nt)
        attribute_planes(
            self._setup, self._tbox, sc.tris, winv, normals, pos, sc.vcol, sc.uv,
            cam.eye, cam._basis[2], cam.orthographic, self._light_dir, self._planes,
        )  # fmt: skip
        tex = self.texture if self.texture is not None else np.ones((1, 1, 3), np.float32)
        m = self.material
        srgb = out8 is not None
        shade_resolve(
            self.ssaa,
            self._bbox,
            self._tid,
            self._planes,
            tex,
            sc.tri_tex,
            self._light_dir,
            self._light_col,
            np.asarray(m.ambient, dtype=np.float64),
            float(m.specular),
            float(m.shininess),
            self._background,
            _SRGB_LUT,
            srgb,
            out8 if srgb else _NO_U8,
            _NO_F32 if srgb else outf,
            nt,
            self._wplanes,
            self._wflag if self._wrinkled else _NO_FLAG,
            self.wrinkles.k if self.wrinkles is not None else 0.0,
            self._spec,
        )

    def _clip_to_mouth(self, scr) -> None:
        """Limit the pixel boxes of the mouth's inside (cavity, teeth, tongue) to the box of
        the lips' inner margin on screen: nothing in the mouth is seen but through it (the
        skin hides the rest), so the rasterizer need not fill the hidden parts."""
        sc = self.scene
        loop, first = sc.cavity
        k = len(loop)
        xy = scr[first : first + k, :2]
        if (scr[first : first + k, 2] < 1.0).any():
            return  # the margin crosses the near plane: leave the boxes alone
        x0, y0 = np.floor(xy.min(axis=0)).astype(np.int64) - 1
        x1, y1 = np.ceil(xy.max(axis=0)).astype(np.int64) + 1
        n_dyn = len(sc.dyn_tris)
        for lo, hi in ((n_dyn - 3 * k, n_dyn), (self._teeth_tri0, len(sc.tris))):
            tb = self._tbox[lo:hi]
            drawn = tb[:, 0] <= tb[:, 1]
            np.maximum(tb[:, 0], x0, out=tb[:, 0])
            np.minimum(tb[:, 1], x1, out=tb[:, 1])
            np.maximum(tb[:, 2], y0, out=tb[:, 2])
            np.minimum(tb[:, 3], y1, out=tb[:, 3])
            empty = (tb[:, 2] > tb[:, 3]) | ~drawn
            tb[empty, 0] = 1
            tb[empty, 1] = 0

    def _wrinkle_planes(self, skin, world_skin, winv) -> None:
        """The wrinkled skin triangles' planes for :func:`raster._shade` (after the set-up)."""
        self._wrinkled = False
        if self.wrinkles is None:
            return
        fields, any_ = self.wrinkles.fields_fast(skin)
        self._wrinkled = any_
        if not any_:
            self._wflag[:] = False
            return
        wrinkle_planes(
            fields, np.ascontiguousarray(world_skin), self._face_tris, self._setup, winv,
            self._wplanes, self._wflag,
        )  # fmt: skip

    def triangle_ids(self) -> np.ndarray:
        """Per-pixel triangle index of the last render at supersampled size (-1: background);
        indices below ``face.n_triangles`` are skin triangles."""
        out = np.full(self._tid.shape, -1, np.int32)
        x0, x1, y0, y1 = self._bbox
        if x0 <= x1 and y0 <= y1:
            out[y0 : y1 + 1, x0 : x1 + 1] = self._tid[y0 : y1 + 1, x0 : x1 + 1]
        return out


def render_mesh(
    vertices: np.ndarray,
    triangles: np.ndarray,
    camera: Camera,
    *,
    colors=None,
    uv=None,
    texture=None,
    lights: list[Light] | None = None,
    material: SkinMaterial | None = None,
    ssaa: int = 1,
    linear: bool = False,
) -> np.ndarray:
    """Render any triangle mesh (vertices (N, 3) mm, triangles (F, 3)) to (H, W, 3).

    ``colors`` (N, 3) linear albedo per vertex (default white); ``uv`` (N, 2) + ``texture`` for
    texture mapping. Returns uint8 sRGB, or float32 linear RGB with ``linear=True``.
    """
    v = _check_vertices(vertices, len(np.asarray(vertices)))
    face = FaceMesh(v, np.asarray(triangles), uv if uv is not None else None, None, {})
    r = Renderer(face, camera, lights, material, texture, ssaa=ssaa, dress=False)
    if colors is not None:
        col = np.asarray(colors, dtype=np.float64)
        if col.shape != (len(v), 3):
            raise MyofaceValueError(f"colors must have shape ({len(v)}, 3); got {col.shape}")
        r.scene.vcol[: len(v)] = col
    out = r.render_linear()
    return out if linear else to_srgb8(out)


def resize_nearest(image: np.ndarray, height: int) -> np.ndarray:
    """Nearest-neighbour resize of an (H, W, 3) image to ``height`` rows (aspect kept)."""
    h, w = image.shape[:2]
    width = max(2, int(round(w * height / h)))
    rows = np.minimum((np.arange(height) + 0.5) * h / height, h - 1).astype(int)
    cols = np.minimum((np.arange(width) + 0.5) * w / width, w - 1).astype(int)
    return image[rows][:, cols]
