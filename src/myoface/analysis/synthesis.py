"""Analysis by synthesis: the tracker's own bias measured on the model's rendering, and removed.

Beyond the paper. A snake settles where its internal forces balance the image's; on a lip whose
outline bends and whose shading changes as a muscle pulls it, that balance point drifts off the
true outline by a few tenths of a pixel, and the curve fit reads that drift as contraction (or
fails to see contraction). The drift is the same on any image that looks the same, so it can be
measured on one whose truth is known: the face model itself, deformed by the current estimate
and rendered as the video shows it.

:class:`FrameSynthesizer` renders the model with the calibration frame as its texture (each skin
vertex's texture coordinate is where the camera saw it on that frame: projective texturing, as
in model-based video coding), divided by the renderer's own shading so that the rest shape
renders back to the calibration frame.
:meth:`~myoface.analysis.curvefit.CurveEstimator.synthesis_step` is one Gauss-Newton step on
the contractions ``c`` that makes the contours tracked on the synthetic frame at ``c`` agree
with those tracked on the real one:

    r_video(n) - [r_synth(n; c) - r_synth(n; 0)] = a(n) . dc

with r the distances, along the contour's normal, from the model's predicted node ``n`` to a
tracked contour, and ``a`` the curve fit's rows. At the true contractions the synthetic frame
is the real one, the two trackings agree and the step is zero, whatever the tracker's bias.

:class:`LandmarkSynthesis` does the same for the landmark tracker's 3-D fit: MediaPipe run on
the person's face rendered at the fit's estimate measures MediaPipe's own error there.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import distance_transform_edt

from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.errors import MyofaceValueError
from myoface.face import FaceMesh
from myoface.facemesh import FaceMeshDetector
from myoface.render import Camera, Renderer
from myoface.render.renderer import load_texture


class FrameSynthesizer:
    """Renders the face model as ``frame`` (the calibration frame, (H, W, 3) or (H, W) uint8)
    showed it.

    ``camera`` maps the model's rest shape onto ``frame`` (the camera the frame was taken
    with, or one fitted to it). Lights and material are the renderer's defaults; the texture
    absorbs whatever they do not explain at rest."""

    def __init__(self, face, camera, frame: np.ndarray, ssaa: int = 2, teeth: bool = True):
        img = np.asarray(frame)
        if img.ndim == 2:
            img = np.repeat(img[:, :, None], 3, axis=2)
        if img.ndim != 3 or img.shape[2] < 3:
            raise MyofaceValueError(f"the frame must be an (H, W, 3) image; got {img.shape}")
        h, w = img.shape[:2]
        if (camera.height, camera.width) != (h, w):
            raise MyofaceValueError(
                f"the camera is {camera.width}x{camera.height} px but the frame {w}x{h}"
            )
        px = camera.project(face.vertices)[:, :2]
        uv = np.column_stack([px[:, 0] / w, 1.0 - px[:, 1] / h])
        textured = FaceMesh(face.vertices, face.triangles, uv, None, face.landmarks)
        white = np.ones((h, w, 3), np.float32)
        self.renderer = Renderer(textured, camera, texture=white, ssaa=ssaa, teeth=teeth)
        # what the renderer adds to and multiplies the texture by at rest
        lit = self.renderer.render_linear()
        matte = Renderer(
            textured,
            camera,
            material=_matte(self.renderer.material),
            texture=white,
            ssaa=ssaa,
            teeth=teeth,
        ).render_linear()
        gloss = lit - matte
        skin = self.renderer.triangle_ids()[:: self.renderer.ssaa, :: self.renderer.ssaa]
        skin = (skin >= 0) & (skin < face.n_triangles)
        if not skin.any():
            raise MyofaceValueError("the camera does not see the face on the frame")
        albedo = (load_texture(img[:, :, :3]) - gloss) / np.maximum(matte, 1e-3)
        # skin that the calibration frame did not show (the inner lips, behind the eyelids)
        # takes the colour of the nearest skin it did
        _, (iy, ix) = distance_transform_edt(~skin, return_indices=True)
        albedo = np.clip(albedo[iy, ix], 0.0, 1.0)
        self.renderer.texture = np.ascontiguousarray(albedo, dtype=np.float32)

    def render(self, skin_vertices: np.ndarray, jaw=None) -> np.ndarray:
        """The synthetic frame (H, W, 3) uint8 of the skin at ``skin_vertices``, the lower
        teeth and the tongue moved by the jaw's rigid motion ``jaw`` (None: closed; see
        :meth:`myoface.model.FaceModel.jaw_pose`)."""
        return self.renderer.render(skin_vertices, jaw=jaw)


def _matte(material):
    """``material`` without its specular highlight."""
    return replace(material, specular=0.0)


class LandmarkSynthesis:
    """The tracker's own error, measured on the model: the person's face rendered at the fit's
    estimate (head pose and skin) by the fit's camera, and MediaPipe run on the render; what it
    reports there less where the model's vertices are is its error at that configuration
    (MediaPipe under-reads expressions and turns of the head), taken off the real frame's
    landmarks (:meth:`~myoface.analysis.modelfit.ModelFit.fit`). At the truth the correction is exact up to how well the
    render looks like the frame; the fit then converges to where the tracker sees the model as
    it sees the video.

    Parameters
    ----------
    face : FaceMesh with the person's texture (e.g. ``face from-photo``'s, or
        :meth:`from_frame`), in the default topology.
    camera : PinholeCamera of the frames, principal point at the image's centre.
    size : (width, height) of the frames, pixels.
    detector : as for :class:`~myoface.analysis.trackers.landmark_fit.FitTracker` (default: MediaPipe's face mesh, in the mode
        ``tracking`` says: the synthetic frames are observed like the real ones).
    tracking : :attr:`~myoface.analysis.weights.FitSettings.tracking` of the fit.
    """

    def __init__(self, face, camera: PinholeCamera, size, detector=None, tracking=False):
        w, h = (int(v) for v in size)
        if abs(camera.cx - 0.5 * w) > 1 or abs(camera.cy - 0.5 * h) > 1:
            raise MyofaceValueError("synthesis needs the principal point at the image's centre")
        fov = float(np.degrees(2 * np.arctan(0.5 * h / camera.focal_px)))
        cam = Camera(np.zeros(3), np.array([0.0, 0.0, -1.0]), width=w, height=h, fov_deg=fov)
        self.camera = camera
        self.renderer = Renderer(face, cam)
        self._own_detector = detector is None
        if detector is None:
            detector = FaceMeshDetector(video=tracking)
        self.detector = detector

    @classmethod
    def from_frame(cls, face, camera: PinholeCamera, frame, shape, pose: HeadPose, **kw):
        """With ``frame`` (H, W, 3) as the texture: each vertex of ``shape`` (V, 3) mm, head
        frame, where ``pose`` puts it in the frame (for a face without a texture of the
        person, e.g. the default face: the calibration frame, shading and all)."""
        img = np.asarray(frame)
        h, w = img.shape[:2]
        uv = camera.project(pose.apply(shape))
        uv = np.column_stack([uv[:, 0] / w, 1.0 - uv[:, 1] / h])
        textured = FaceMesh(face.vertices, face.triangles, uv, img, face.landmarks, name=face.name)
        return cls(textured, camera, (w, h), **kw)

    def tracker_error(self, skin: np.ndarray, pose: HeadPose,
                      context: np.ndarray | None = None) -> np.ndarray | None:  # fmt: skip
        """(V, 3): the tracker's points on the model rendered with ``skin`` (V, 3) mm, head
        frame, at ``pose``, less the model's own (x, y pixels; z relative depth, pixels, up to
        a constant); None when the tracker finds no face in the render. ``context``: a frame
        (H, W, 3) uint8 of the video the render is laid over (:meth:`composite`), so that
        the tracker sees the model among what the frame shows around the face (its room,
        hair, neck) rather than on the renderer's plain background."""
        img = self.renderer.render(skin, pose=(pose.rotation, pose.translation_mm))
        if context is not None:
            img = self.composite(img, context)
        q = self.detector.detect(img)
        if q is None:
            return None
        pc = pose.apply(skin)
        uv = self.camera.project(pc)
        z = -pc[:, 2] * self.camera.focal_px / max(-pose.translation_mm[2], 1.0)
        err = np.column_stack([q[:, :2] - uv, q[:, 2] - z])
        err[:, 2] -= err[:, 2].mean()
        return err

    def composite(self, render: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """The last render (``render``, (H, W, 3) uint8) laid over ``frame`` (the same size):
        each pixel mixed by the share of it the render drew the head on
        (:func:`~myoface.render.degrade.coverage`: the head's silhouette anti-aliased), the
        frame's own pixel where the render drew none."""
        from myoface.render.degrade import coverage

        img = np.asarray(frame)
        if img.ndim != 3 or img.shape[:2] != render.shape[:2] or img.shape[2] < 3:
            raise MyofaceValueError(
                f"the context must be an (H, W, 3) image of the render's size {render.shape[:2]};"
                f" got {img.shape}"
            )
        a = coverage(self.renderer)[:, :, None]
        out = a * render.astype(np.float32) + (1.0 - a) * img[:, :, :3].astype(np.float32)
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)

    def close(self) -> None:
        self.detector.close()
