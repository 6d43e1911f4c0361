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
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import distance_transform_edt

from myoface.errors import MyofaceValueError


class FrameSynthesizer:
    """Renders the face model as ``frame`` (the calibration frame, (H, W, 3) or (H, W) uint8)
    showed it.

    ``camera`` maps the model's rest shape onto ``frame`` (the camera the frame was taken
    with, or one fitted to it). Lights and material are the renderer's defaults; the texture
    absorbs whatever they do not explain at rest."""

    def __init__(self, face, camera, frame: np.ndarray, ssaa: int = 2, teeth: bool = True):
        from myoface.face import FaceMesh
        from myoface.render import Renderer
        from myoface.render.renderer import load_texture

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
    from dataclasses import replace

    return replace(material, specular=0.0)
