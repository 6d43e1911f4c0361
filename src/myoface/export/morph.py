"""The skin's motion as morph targets: one per muscle (the model's simulated response to it)
plus corrective targets baked from the clip's own frames where the tissue is not linear.

A morph-target animation shows, at frame k, ``rest + sum_j w_kj D_j``. The physics is not a
linear function of the contractions (the springs' stiffening, the volume constraint, the lids
sliding over the eyeballs, the lips kept out of the teeth), so the muscles' responses alone
(``D_i = skin(e_i) - rest``, weights = the contractions) leave a residual; it is measured per
frame, and its principal components (an SVD of the residuals of all frames) are added as
corrective targets, as few as bring every frame within ``tol_mm`` RMS. The muscle targets keep
their meaning for an animator (target ``zygomaticus_major_l`` at weight 0.6 is that muscle's
response scaled to 0.6); the correctives carry what the linear sum misses.

Lengths are millimetres here; the glTF writer converts to metres.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceWarning

#: default largest RMS (mm) over the skin's vertices that any exported frame may be from the
#: simulated skin: a fifth of the 0.5 mm the export promises (issue 33), so the float32 of the
#: file and a client's own interpolation have room
DEFAULT_TOL_MM = 0.1
#: at most this many corrective targets (beyond it the frames themselves are cheaper)
MAX_CORRECTIVES = 256
#: a corrective's half (its positive or negative side) whose weights never pass this is left
#: out: at most this fraction of the component (a few mm at most) is lost, under a micrometre
UNUSED_WEIGHT = 1e-4


def frame_rms_mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-frame RMS distance (T,) between two skin sequences (T, V, 3) (their units): the
    square root of the mean over vertices of the squared distance."""
    d = np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.sqrt((d**2).sum(axis=2).mean(axis=1))


def muscle_responses(model) -> np.ndarray:
    """Each muscle's (and the jaw's) response ``skin(e_i) - rest`` (M, V, 3) mm: the skin at
    the equilibrium of that contraction alone at 1 (``myoface.synth.SYNTH_TOL_MM``), minus the
    rest skin; computed once per model (:meth:`~myoface.model.FaceModel.memo`)."""
    from myoface.synth import SYNTH_TOL_MM

    def compute():
        rest = model.skin_vertices()
        out = np.empty((model.n_muscles, model.face.n_vertices, 3))
        for i in range(model.n_muscles):
            c = np.zeros(model.n_muscles)
            c[i] = 1.0
            out[i] = model.skin_vertices(model.relax(c, tol_mm=SYNTH_TOL_MM).state) - rest
        out.flags.writeable = False
        return out

    return model.memo(("export.muscle_responses", SYNTH_TOL_MM), compute)


@dataclass(frozen=True, eq=False)
class MorphAnimation:
    """Morph targets and their weights per frame.

    Attributes
    ----------
    rest : (V, 3) mm — the base mesh.
    targets : (K, V, 3) mm — displacements from ``rest``.
    weights : (T, K) — per frame.
    names : list of str — one per target (muscle ids, then ``corrective_NNp`` / ``NNn``).
    n_muscle_targets : int — the first this many are the muscles' responses.
    frame_rms_mm : (T,) — each frame's RMS from the skin it was fitted to.
    linear_rms_mm : (T,) — each frame's RMS with the muscle targets alone (the tissue's
        departure from linearity on this clip).
    """

    rest: np.ndarray
    targets: np.ndarray
    weights: np.ndarray
    names: list
    n_muscle_targets: int
    frame_rms_mm: np.ndarray
    linear_rms_mm: np.ndarray

    @property
    def n_targets(self) -> int:
        return len(self.targets)

    def evaluate(self) -> np.ndarray:
        """The skin (T, V, 3) mm the targets and weights give."""
        return self.rest[None] + np.einsum("tk,kvc->tvc", self.weights, self.targets)


def fit_morph_animation(
    skin: np.ndarray,
    rest: np.ndarray,
    contractions: np.ndarray,
    responses: np.ndarray,
    names,
    *,
    tol_mm: float = DEFAULT_TOL_MM,
    max_correctives: int = MAX_CORRECTIVES,
) -> MorphAnimation:
    """Morph targets reproducing ``skin`` (T, V, 3) mm: the muscle ``responses`` (M, V, 3)
    weighted by the ``contractions`` (T, M), plus the fewest principal components of the
    residual that bring every frame within ``tol_mm`` RMS, each scaled so that its weights stay
    within [-1, 1] and split into a positive and a negative target (``corrective_NNp``,
    ``corrective_NNn``) so that every weight is in [0, 1]. Muscles that never contract in the
    clip get no target."""
    skin = np.asarray(skin, dtype=np.float64)
    rest = np.asarray(rest, dtype=np.float64)
    c = np.asarray(contractions, dtype=np.float64)
    n_t, n_v = skin.shape[:2]
    used = np.flatnonzero(np.abs(c).max(axis=0) > 0)
    lin_targets = np.asarray(responses)[used]
    lin_w = c[:, used]
    linear = rest[None] + np.einsum("tk,kvc->tvc", lin_w, lin_targets)
    linear_rms = frame_rms_mm(linear, skin)
    resid = (skin - linear).reshape(n_t, -1)
    k = 0
    u = s = vt = None
    if linear_rms.max() > tol_mm:
        u, s, vt = np.linalg.svd(resid, full_matrices=False)
        # each frame's residual after the first k components: sum of the squares left
        left = (resid**2).sum(axis=1)
        proj = (u * s[None]) ** 2  # (T, r): the square of each component in each frame
        cum = np.cumsum(proj, axis=1)
        limit = min(max_correctives, len(s))
        for k in range(1, limit + 1):
            rms = np.sqrt(np.maximum(left - cum[:, k - 1], 0.0) / n_v)
            if rms.max() <= tol_mm:
                break
        if rms.max() > tol_mm:
            warnings.warn(
                f"{k} corrective targets (the most) leave a frame {rms.max():.3f} mm RMS from "
                f"the simulated skin, above the {tol_mm:g} mm asked for",
                MyofaceWarning,
                stacklevel=2,
            )
    targets = [lin_targets]
    weights = [lin_w]
    corr_names = []
    if k:
        w = u[:, :k] * s[None, :k]  # (T, k)
        scale = np.abs(w).max(axis=0)
        scale[scale == 0] = 1.0
        comp = (vt[:k] * scale[:, None]).reshape(k, n_v, 3)
        w = w / scale[None]
        # each component as two targets, +D and -D, each weighted in [0, 1]: clients that
        # clamp weights to a range (Unity's legacyClampBlendShapeWeights; Blender 3.4's
        # importer clamps below the first keyframe's value) play it as written; a half never
        # used (no weight above UNUSED_WEIGHT: rounding's, which would otherwise make the count
        # vary between runs) is left out
        for j in range(k):
            for sign, tag in ((1.0, "p"), (-1.0, "n")):
                wj = np.maximum(sign * w[:, j], 0.0)
                if wj.max() > UNUSED_WEIGHT:
                    targets.append(sign * comp[j : j + 1])
                    weights.append(wj[:, None])
                    corr_names.append(f"corrective_{j:02d}{tag}")
    names = [str(names[i]) for i in used] + corr_names
    m = MorphAnimation(
        rest,
        np.concatenate(targets),
        np.concatenate(weights, axis=1),
        names,
        len(used),
        np.zeros(n_t),
        linear_rms,
    )
    object.__setattr__(m, "frame_rms_mm", frame_rms_mm(m.evaluate(), skin))
    return m


def least_squares_rms_mm(skin, rest, contractions, responses) -> np.ndarray:
    """The best a linear basis of the muscles' responses can do: per frame (T,), the RMS (mm)
    of ``skin`` (T, V, 3) from ``rest`` + the responses of the muscles that contract in the
    clip weighted by the least-squares weights of that frame (free, not the contractions)."""
    skin = np.asarray(skin, dtype=np.float64)
    c = np.asarray(contractions, dtype=np.float64)
    used = np.flatnonzero(np.abs(c).max(axis=0) > 0)
    d = (skin - np.asarray(rest)[None]).reshape(len(skin), -1)
    if not len(used):
        return frame_rms_mm(skin, np.broadcast_to(rest, skin.shape))
    a = np.asarray(responses)[used].reshape(len(used), -1)  # (K, 3V)
    w, *_ = np.linalg.lstsq(a.T, d.T, rcond=None)
    fit = (w.T @ a).reshape(skin.shape) + np.asarray(rest)[None]
    return frame_rms_mm(fit, skin)
