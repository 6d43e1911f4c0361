"""The paper's tracker: snakes on the face's feature contours, a head frame, and the
contractions read off the contours (the curve fit or the paper's fiducials) each frame
(Terzopoulos & Waters 1993, Section V).

:class:`Analyzer` is the snakes' analysis, made from initial contours on the calibration frame
(the first frame it measures); :class:`SnakeTracker` is it behind the trackers' protocol
(:mod:`myoface.analysis.trackers.base`), finding the initial contours with MediaPipe's face
mesh on the first frame with a face when none are given.
"""

from __future__ import annotations

import numpy as np

from myoface.analysis.curvefit import CurveEstimator
from myoface.analysis.estimate import ContractionEstimator
from myoface.analysis.headframe import HeadTracker, Similarity, head_box
from myoface.analysis.landmarks import auto_init, rigid_vertices, similarity_affine
from myoface.analysis.potentials import (
    MouthTones,
    PotentialField,
    bilinear,
    potential_field,
    potential_image,
    pseudo_hue,
    saturation,
    to_intensity,
)
from myoface.analysis.sections import (
    CURVE_EXCLUDED,
    FEATURES,
    LINE_SECTIONS,
    PAPER_MUSCLES,
    SECTIONS,
    curve_centroid,
    model_fiducials,
    section_features,
    section_vertices,
)
from myoface.analysis.snakes import SnakeParams, Snakes, make_contours, resample_polyline
from myoface.analysis.synthesis import FrameSynthesizer
from myoface.analysis.trackers.base import FrameMeasurement, TrackerBase
from myoface.errors import MyofaceDependencyError, MyofaceValueError
from myoface.facemesh import FaceMeshDetector

#: the potential's Gaussian width on the face, mm (``sigma=None``): features are blurred by
#: the same amount of skin whatever the face's size in pixels (1.5 px on the 256 x 256
#: closed-loop frames, where a pixel is 0.77 mm)
SIGMA_MM = 1.2
#: how contractions are read off the contours (see :class:`Analyzer`)
ESTIMATORS = ("curves", "fiducials")
#: a frame is unusable when more than this fraction of a contour's nodes escaped its edge
ESCAPE_LIMIT = 0.5
#: ... or when its strongest edges are weaker than this fraction of the calibration frame's
LOW_CONTRAST = 0.35
#: ... or when a contour lies farther (RMS across it, mm on the face) from the model's curve at
#: the fitted contractions than any shape the model takes explains: the contour is on something
#: else (an occluding hand, the inside of the mouth)
MISFIT_MM = 6.0
#: ... or when the head turned about its vertical axis from the calibration frame's pose so far
#: that the registered eye-and-nose region is narrower, relative to its height, than this
#: (:attr:`~myoface.analysis.headframe.HeadTracker.foreshortening`): the 2-D analysis reads
#: the turned face as muscle action. Measured on the model rendered turned while smiling:
#: 1.000 / 0.978 / 0.959 / 0.938 at 4 / 8 / 12 / 16 degrees, with the far side's zygomatic
#: major already 0.21 / 0.18 too high at 4 / 8 degrees; the sample video's smile raises it to
#: 1.0-1.09 (the eyes narrow), so a smile is not taken for a turn. About 10 degrees:
HEAD_TURN_FORESHORTENING = 0.965
#: a contour of the video tracker is at rest (and stops while the others go on) when none of
#: its nodes moved by more than this across it over the last 10 iterations (px; SnakeParams'
#: 0.1 stopped the whole system only when every contour was at rest, so that on real video
#: every relaxation ran its 300 iterations). Measured on the sample video: at 0.07 (and 0.05,
#: 0.03) the contours follow the smile as before (the zygomatic majors' mean over the smile
#: 1.00 on both sides); at 0.1 they stop while still creeping towards weak edges at 0.01 px
#: per iteration, and the right side's mean falls to 0.28. (On the closed loop with analysis
#: by synthesis the worst RMSE varies between 0.041 and 0.052 for tolerances 0.02-0.1, with
#: no trend: the depressors' sub-pixel signal.)
TRACK_TOL_PX = 0.07
#: the second pass from the model's prediction is left out when the first estimate is within
#: this (contraction, every muscle) of the last frame's and every contour held: the contours
#: are then where the last frame's second pass put them
RESEED_STEP = 0.05
#: the potentials are computed on a window around the contours: their bounding box grown by
#: this fraction of its size, plus WINDOW_PAD_PX (room for the contours to move in one frame)
WINDOW_MARGIN = 0.15
WINDOW_PAD_PX = 8.0
#: sections whose outline encloses the mouth: they move in a layer of their own, the edge
#: potential of the frame with everything darker than the lips raised to the lips' own dark
#: tone (:func:`lips_tone`), so that the mouth's inside, dark as the lips part, makes no
#: edge. Without it the lips' snake, on the outer margin, is drawn to the inner one where the
#: lower lip is thin (near the corners when the jaw opens and the depressors pull it down):
#: measured on the closed loop's frames with the mouth's cavity rendered, up to 2.6 mm (3.4
#: px) inside the outline, against 0.8 mm with the mouth drawn shut
MOUTH_SECTIONS = ("lips",)
#: the band inside a mouth section's outline (mm on the face) whose grey levels give the
#: lips' tone, and the percentile of them taken (:func:`lips_tone`): the lips' darker quarter.
#: On the closed loop's 48 frames with analysis by synthesis (``myoface bench --only
#: analysis.closed_loop_rmse``) the depressors' RMSE was 0.042-0.045 with the 25th
#: percentile, 0.049-0.052 with the 10th (the floor 72 and 53 grey levels; the cavity ~15, the
#: lower lip near the corners 95-115, the skin beside it 155-170)
MOUTH_BAND_MM = (0.5, 2.5)
#: with ``mouth_colour``, the mouth sections relax first in a copy of their layer blurred this
#: many times more (its ravines deepened as much), which reaches farther: as the sample
#: video's smile opens the upper lip's border rises 22 px above the lips' outline at rest
MOUTH_COARSE = 3.0
#: the teeth in the mouth sections' layer (:func:`~myoface.analysis.potentials.mouth_image`):
#: pixels less saturated than this fraction of the skin's around the lips (measured on the
#: calibration frame, MOUTH_BAND_MM outside the outline). On the sample video the skin there
#: is at 0.40, the lips at 0.47, the teeth of the smile at 0.23-0.30
TEETH_SATURATION = 0.75
MOUTH_FLOOR_PERCENTILE = 25.0


# ------------------------------------------------------------------------------ the analyzer


def lips_tone(
    frame: np.ndarray,
    contour: np.ndarray,
    band_px=(1.0, 3.0),
    percentile: float = MOUTH_FLOOR_PERCENTILE,
) -> float:
    """The lips' dark tone on ``frame``: the ``percentile`` of the grey levels (0-255) in the
    band ``band_px`` (px) inside the closed ``contour`` ((K, 2) image (x, y) px, the lips'
    outer outline), sampled along each node's inward normal."""
    vals = _band(np.ascontiguousarray(to_intensity(frame)), contour, band_px, 1)
    return float(np.percentile(vals, percentile))


def _band(img: np.ndarray, contour: np.ndarray, band_px, sign: int) -> np.ndarray:
    """``img`` (H, W) sampled in the band ``band_px`` (px) inside (``sign`` 1) or outside
    (-1) the closed ``contour`` ((K, 2) image (x, y) px), along each node's normal."""
    q = np.asarray(contour, dtype=np.float64)
    tan = np.roll(q, -1, axis=0) - np.roll(q, 1, axis=0)
    nrm = np.stack([-tan[:, 1], tan[:, 0]], axis=1)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1), 1e-12)[:, None]
    # the normal (-ty, tx) points inwards on a contour running clockwise on the screen (y
    # down: positive shoelace area)
    area = 0.5 * np.sum(q[:, 0] * np.roll(q[:, 1], -1) - np.roll(q[:, 0], -1) * q[:, 1])
    if area < 0:
        nrm = -nrm
    depths = sign * np.linspace(band_px[0], band_px[1], 5)
    pts = (q[:, None, :] + depths[None, :, None] * nrm[:, None, :]).reshape(-1, 2)
    return np.array([bilinear(img, x, y) for x, y in pts])


def _init_mm_per_px(model, init: dict) -> float:
    """The face's scale in initial contours: RMS radius of the model's section curves (mm)
    over that of the contours (px)."""
    mm = np.concatenate([model.face.vertices[section_vertices(model.face, s), :2] for s in init])
    px = np.concatenate([np.asarray(init[s], dtype=np.float64) for s in init])
    r_mm = np.sqrt(((mm - mm.mean(0)) ** 2).sum(1).mean())
    r_px = np.sqrt(((px - px.mean(0)) ** 2).sum(1).mean())
    if not r_px > 0:
        raise MyofaceValueError("the initial contours are degenerate (a single point)")
    return float(r_mm / r_px)


class Analyzer:
    """Tracks the feature contours of a face video and estimates contractions per frame.

    Parameters
    ----------
    model : FaceModel — its muscles are estimated; its face gives the landmark groups.
    init : {section: (K, 2)} initial contours in the calibration frame (pixels); sections may
        be missing (their fiducials are then not used).
    muscle_ids : muscles to estimate (default: the paper's 12 + jaw).
    refine : Gauss-Newton corrections per frame through the model (0: linear estimate only).
    sigma : Gaussian width (px) of the image potential; None (default): :data:`SIGMA_MM` on
        the face, converted with the face's scale in the initial contours. ``potential``: see
        :func:`~myoface.analysis.potentials.image_potential`.
    head_frame : ``"register"`` (default): the head's similarity motion (translation, scale,
        in-plane rotation) from image registration of the upper face
        (:class:`~myoface.analysis.headframe.HeadTracker`); the contours are carried along
        with it before they relax on each frame. ``"contours"``: the paper's scheme, the
        translation of the ``head_reference`` sections' centroid (the paper uses the
        hairline).
    head_reference : sections for ``head_frame="contours"``.
    estimator : ``"curves"`` (default; beyond the paper): the model's skin curves fitted to
        the whole contours, distances along the contours' normals
        (:class:`~myoface.analysis.curvefit.CurveEstimator`). ``"fiducials"``: the paper's
        scheme, fiducial points read off the contours (:func:`section_features`) and inverted
        jointly by :class:`~myoface.analysis.estimate.ContractionEstimator`.
    line_sections : sections tracked in the ``"line"`` potential (thin dark lines) instead of
        ``potential``.
    mouth_sections : sections around the mouth, tracked in ``potential`` with the mouth's
        inside no darker than the lips (e.g. :data:`MOUTH_SECTIONS`; the lips' tone measured
        on the calibration frame). Off by default: on the sample video's smile it drew the
        right zygomatic major's estimate from 0.95-1.0 down to 0.3-0.55 and lost a nasolabial
        contour (misfit), while on the closed loop's renders it kept the lips' snake on the
        outline.
    mouth_colour : with ``mouth_sections``, their layer made from the lips' colour instead
        (:func:`~myoface.analysis.potentials.mouth_image`: the pseudo-hue R / (R + G) between
        the skin's and the lips', measured on the calibration frame, with the teeth, the
        mouth's dark inside and what the lips enclose taken as lips), keeping only the edges
        whose grey levels rise outwards from the lips' middle (the teeth's edges with the
        lips, inside the outline, make none), and a coarse copy (:data:`MOUTH_COARSE`) the
        sections relax in first. Off by default: it weakens the fiducial estimator on a
        synthetic smile (``tests/test_cli_analyze.py``, correlation 0.67 < 0.7) and leaves a
        frame of a batch's synthetic smile unmeasured, not yet understood; with the depressor
        labii inferioris as a sheet (the default set since 2026-12-02) the snakes without it
        read the sample's smile's zygomatic majors at 0.27-0.33, with it at 0.92 (the left one
        0.62 on the last frame). Measured 2026-12-02 on the sample video's
        open smile (frames 25-64, means; ``python tools/snake_lips.py --colour``, against
        MediaPipe's outline): the snakes' top went from 5.7 px below the upper lip's border
        (on the upper teeth) to 0.5 px, their bottom from 12.6 px above the lower lip's (on
        the lower teeth's edge) to 4.2 px, but the subject's left corner stays inside (9.1 ->
        11.6 px) and the right one goes out (1.9 -> 4.9 px); with the bundled muscles the fit
        then reads the right zygomatic major at 0.39 over the smile (1.00 without; with the
        depressor labii inferioris as a sheet, d585611's muscle file: 1.00 and the left one
        0.94, with the outline's top 0.5, bottom 4.2, corners 1.0 and 15.0 px). On the closed
        loop (24 frames at 256 px, ``run_closed_loop``, the mouth drawn shut) the worst RMSE
        went 0.255 -> 0.129 (the depressors 0.21-0.26 -> 0.10-0.13, frontalis_outer_r 0.056 ->
        0.025), with the teeth rendered 0.296 -> 0.138 (the plain mouth layer: 0.281), and
        with the sheet 0.099 -> 0.052.
    reseed : with ``estimator="curves"``, a second pass per frame: the contours are moved to
        where the model, at the first estimate, puts their skin, relaxed again and the
        contractions re-estimated (analysis by synthesis; twice the tracking cost).
    synthesis : a :class:`~myoface.render.Camera` that maps the model's rest shape onto the
        calibration frame, or None (default). With ``estimator="curves"``, the model is then
        rendered as the calibration frame showed it, deformed by each frame's estimate,
        tracked like the video, and ``synthesis_rounds`` Gauss-Newton steps remove the
        tracker's own bias (:mod:`myoface.analysis.synthesis`; one render, one tissue relax
        and one tracking per round).
    deferred_relax : with ``estimator="curves"`` and without ``synthesis``: True, each
        frame's estimate is the fit of the model as the tissue was last relaxed (a frame
        earlier: :attr:`~myoface.analysis.curvefit.CurveEstimator.linearisation`; at once
        after a step beyond :data:`~myoface.analysis.curvefit.DEFER_STEP`), and the
        ``refine`` relax at it runs on a second thread while the next frame is tracked (what
        :func:`make_analyzer` chooses for a video: about 1.3x the frame rate on two cores,
        for an error up to 0.01 larger on the closed loop). False (default): the relax
        corrects the frame's own estimate first.
    """

    def __init__(
        self,
        model,
        init: dict[str, np.ndarray],
        muscle_ids=PAPER_MUSCLES,
        refine: int = 1,
        sigma: float | None = None,
        params: SnakeParams | None = None,
        spacing_px: float = 1.0,
        potential: str = "gaussian",
        head_frame: str = "register",
        head_reference=("nose",),
        estimator: str = "curves",
        line_sections=LINE_SECTIONS,
        mouth_sections=(),
        mouth_colour: bool = False,
        reseed: bool = True,
        synthesis=None,
        synthesis_rounds: int = 3,
        deferred_relax: bool = False,
        synthesis_teeth: bool = True,
    ):
        #: whether the synthesized frames show the teeth and the mouth's cavity (as a video
        #: does) or the mouth drawn shut (frames rendered so, e.g. the closed loop's)
        self.synthesis_teeth = bool(synthesis_teeth)
        if estimator not in ESTIMATORS:
            raise MyofaceValueError(f"estimator must be one of {ESTIMATORS}; got {estimator!r}")
        self.method = estimator
        self.reseed = bool(reseed)
        self._calibration_index = None
        if head_frame not in ("register", "contours"):
            raise MyofaceValueError(
                f"head_frame must be 'register' or 'contours'; got {head_frame!r}"
            )
        self.head_frame = head_frame
        self.head = None  # HeadTracker, made on the calibration frame
        if not init:
            raise MyofaceValueError("no initial contours")
        unknown = set(init) - set(SECTIONS)
        if unknown:
            raise MyofaceValueError(f"unknown sections {sorted(unknown)}; see SECTIONS")
        self.model = model
        self.refine = int(refine)
        self.sigma = float(sigma) if sigma is not None else SIGMA_MM / _init_mm_per_px(model, init)
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise MyofaceValueError(f"sigma must be > 0 pixels; got {self.sigma}")
        self.potential = potential
        self.sections = [s for s in SECTIONS if s in init]
        self.head_reference = [s for s in head_reference if s in self.sections]
        polys, closed = [], []
        for sec in self.sections:
            polys.append(resample_polyline(init[sec], spacing_px, closed=SECTIONS[sec][1]))
            closed.append(SECTIONS[sec][1])
        self.contours = make_contours(polys, closed=closed, names=self.sections)
        self.params = params or SnakeParams(p=0.01, tol_px=TRACK_TOL_PX)
        # the potential's layers: ``potential`` (edges), then the lines' and the mouth's when
        # some section is tracked in them
        kinds = ["edge"]
        for kind, secs in (("line", line_sections), ("mouth", mouth_sections)):
            if any(s in secs for s in self.sections):
                kinds.append(kind)
        if "mouth" in kinds and mouth_colour:
            kinds.append("mouth_coarse")
        self._layer_kinds = tuple(kinds)
        self.layers = [
            kinds.index("line")
            if s in line_sections
            else kinds.index("mouth")
            if s in mouth_sections
            else 0
            for s in self.sections
        ]
        #: the lips' dark tone (grey level) below which the mouth sections' layer raises the
        #: frame (:func:`lips_tone`, measured on the calibration frame; None before)
        self.mouth_floor = None
        self.mouth_sections = tuple(mouth_sections)
        #: whether the mouth sections' layer is made from the lips' colour
        #: (:func:`~myoface.analysis.potentials.mouth_image`), keeps only the edges rising
        #: outwards from the lips' middle, and has a coarse copy they relax in first
        self.mouth_colour = bool(mouth_colour)
        self.snakes = Snakes(self.contours, self.params, layers=self.layers)
        all_fids = {f.name: f for f in model_fiducials(model.face)}
        self.fiducials = [all_fids[f"{s}:{n}"] for s in self.sections for n in FEATURES[s]]
        self.ids = tuple(muscle_ids)
        self.estimator = ContractionEstimator(model, self.fiducials, self.ids)
        self.curves = None
        if estimator == "curves":
            pass

            secs = {
                s: (section_vertices(model.face, s), SECTIONS[s][1])
                for s in self.sections
                if s not in CURVE_EXCLUDED
            }
            self.curves = CurveEstimator(model, secs, self.ids)
        self._p0 = None
        self._ref0 = None
        self._sim = Similarity()
        self.mm_per_px = None
        self._init = {k: np.asarray(v, dtype=np.float64) for k, v in init.items()}
        self._contrast0 = None
        self._frame_shape = None
        self._field = None  # this frame's potentials (PotentialField)
        self._cal_nodes = None  # the contours on the calibration frame
        self._model_map = None  # (matrix, offset): the model's image-like mm -> calibration px
        self._c_last = None  # the last measured contractions
        self._lost = set()  # sections lost on the last frame, re-initialised on this one
        self._shift = np.zeros(2)  # the last head shift (head_frame="contours")
        self._face_lost = False
        self._detector = None  # MediaPipe's face mesh, made when a lost face is searched for
        self.last_residuals_mm = {}  # the last frame's fit residual per section (diagnostic)
        if synthesis is not None and estimator != "curves":
            raise MyofaceValueError("synthesis needs estimator='curves'")
        if not (isinstance(synthesis_rounds, int | np.integer) and synthesis_rounds >= 0):
            raise MyofaceValueError(f"synthesis_rounds must be an int >= 0; got {synthesis_rounds}")
        self.synthesis_camera = synthesis
        self.synthesis_rounds = int(synthesis_rounds)
        self.deferred_relax = bool(deferred_relax)
        self._synth = None  # FrameSynthesizer, made on the calibration frame

    # ------------------------------------------------------------ potentials
    def _mouth_tones(self, frame, conts, band) -> MouthTones:
        """The colours around the mouth sections' outlines ``conts`` on ``frame`` (the
        calibration frame): the skin's in ``band`` (px) outside them, the lips' inside."""
        hue, sat = pseudo_hue(frame), saturation(frame)
        qs = [q for s, q in zip(self.sections, conts, strict=True) if s in self.mouth_sections]

        def median(img, sign):
            return float(np.median(np.concatenate([_band(img, q, band, sign) for q in qs])))

        return MouthTones(
            skin_hue=median(hue, -1),
            lip_hue=median(hue, 1),
            floor=float(self.mouth_floor),
            teeth_saturation=TEETH_SATURATION * median(sat, -1),
        )

    def _methods(self) -> tuple:
        return tuple("line" if k == "line" else self.potential for k in self._layer_kinds)

    def _field_for(self, frame: np.ndarray, nodes: np.ndarray) -> PotentialField:
        """The potentials of ``frame`` (``potential``, then ``"line"`` when some section is
        tracked as a line, then ``potential`` raised to :attr:`mouth_floor` when some section
        is around the mouth) on a window around ``nodes`` ((N, 2) image (x, y) px): the
        contours' box grown by :data:`WINDOW_MARGIN` of its size and :data:`WINDOW_PAD_PX`;
        the other layers (the line's wide blur costs most) only around the contours that
        move in them, the same way."""
        q = np.asarray(nodes, dtype=np.float64)
        box, _ = self._box(frame, q, None)
        layer = self.snakes.node_layer
        kinds = self._layer_kinds
        own = [kinds.index("mouth") if k == "mouth_coarse" else j for j, k in enumerate(kinds)]
        layer_windows = [None] + [
            self._box(frame, q[layer == own[j]], None)[0] for j in range(1, len(kinds))
        ]
        floors = [self.mouth_floor if k.startswith("mouth") else None for k in kinds]
        sigmas = [self.sigma * MOUTH_COARSE if k == "mouth_coarse" else None for k in kinds]
        outward = [None] * len(kinds)
        if "mouth" in kinds and self.mouth_colour:
            ell = _ellipse(q[layer == kinds.index("mouth")])
            outward = [ell if k.startswith("mouth") else None for k in kinds]
        return potential_field(
            frame, self.sigma, self._methods(), box, layer_windows, floors, sigmas, outward
        )

    @staticmethod
    def _box(frame, q: np.ndarray, pad: float | None):
        """The box around points ``q`` grown by ``pad`` (default: :data:`WINDOW_MARGIN` of
        its size and :data:`WINDOW_PAD_PX`), and the pad."""
        h, w = np.shape(frame)[:2]
        lo = np.clip(q.min(axis=0), 0, (w - 1, h - 1))
        hi = np.clip(q.max(axis=0), 0, (w - 1, h - 1))
        if pad is None:
            pad = WINDOW_MARGIN * float((hi - lo).max()) + WINDOW_PAD_PX
        return (lo[0] - pad, lo[1] - pad, hi[0] + pad, hi[1] + pad), pad

    def _covers(self, fld: PotentialField, nodes: np.ndarray) -> bool:
        """Whether this frame's potentials ``fld`` hold the contours ``nodes`` (each in its
        layer's window)."""
        m = WINDOW_PAD_PX / 2
        if not fld.covers(nodes, m):
            return False
        layer = self.snakes.node_layer
        return all(
            fld.covers(nodes[layer == j], m, layer=j) for j in range(1, len(self._layer_kinds))
        )

    def _relax(self, frame: np.ndarray, fld: PotentialField | None):
        """Relax the snakes on ``frame``; ``fld`` (this frame's potentials) is reused when its
        windows hold the contours."""
        nodes = self.snakes.contours.nodes
        if fld is None or not self._covers(fld, nodes):
            fld = self._field_for(frame, nodes)
        self._field = fld
        if "mouth_coarse" in self._layer_kinds and self.mouth_floor is not None:
            # the mouth's sections first in the coarse copy of their layer, from wherever the
            # frame before or the model put them, then in their own
            lay = self.snakes.node_layer
            mouth = lay == self._layer_kinds.index("mouth")
            lay[mouth] = self._layer_kinds.index("mouth_coarse")
            try:
                self.snakes.relax(fld)
            finally:
                lay[mouth] = self._layer_kinds.index("mouth")
        return self.snakes.relax(fld), fld

    @property
    def last_potential(self) -> np.ndarray:
        """The last frame's potential (H, W) (its first layer; 0 outside the window it was
        computed on, and everywhere when the face was lost): the overlay of the paper's
        Fig. 7b."""
        if self._field is None:
            return np.zeros(self._frame_shape or (1, 1))
        return self._field.full_layer(0)

    # ------------------------------------------------------------ contours and the head
    def _features(self, conts: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        allpts = np.concatenate(conts)
        named = dict(zip(self.sections, conts, strict=True))
        mid = curve_centroid(named["nose"], False)[0] if "nose" in named else allpts[:, 0].mean()
        feats = np.concatenate([section_features(s, named[s], mid) for s in self.sections])
        ref = (
            np.concatenate([named[s] for s in self.head_reference]).mean(axis=0)
            if self.head_reference
            else np.zeros(2)
        )
        return feats, ref

    def _to_calibration(self, conts: list[np.ndarray]) -> list[np.ndarray]:
        """Contours in the calibration frame's coordinates (the registered head motion
        removed; with ``head_frame="contours"`` the shift is removed later)."""
        if self.head_frame == "register":
            return self.contours.split(self._sim.inverse_apply(np.concatenate(conts)))
        return conts

    def _head_shift(self, conts_cal: list[np.ndarray]) -> np.ndarray:
        """``head_frame="contours"``: the head reference sections' shift from the calibration
        frame (px); zero with the registered head frame (already removed)."""
        if self.head_frame == "register" or not self.head_reference:
            return np.zeros(2)
        named = dict(zip(self.sections, conts_cal, strict=True))
        return np.concatenate([named[s] for s in self.head_reference]).mean(axis=0) - self._ref0

    def _fit_curves(self, conts_cal: list[np.ndarray], shift: np.ndarray) -> np.ndarray:
        named = {s: q - shift for s, q in zip(self.sections, conts_cal, strict=True)}
        return self.curves.estimate(named, refine=self.refine)

    def _escaped(self, res) -> list[str]:
        """Sections of which more than :data:`ESCAPE_LIMIT` of the nodes lost their edge or
        left the image."""
        sizes = np.diff(self.contours.offsets)
        return [
            s
            for s, e, n in zip(self.sections, res.escaped, sizes, strict=True)
            if e > ESCAPE_LIMIT * n
        ]

    def _predicted_sections(self, c, shift) -> dict[str, np.ndarray]:
        """Where the model puts each section's nodes on the current frame: the curve fit's
        prediction for contractions ``c`` (sections it fits; the calibration contours for
        the others, or for every section when ``c`` is None), moved by the current head
        pose (the registered similarity, or ``shift``)."""
        out = {}
        if self.curves is not None and c is not None and np.isfinite(c).all():
            pred = self.curves.predict(c)
            sizes = dict(zip(self.sections, np.diff(self.contours.offsets), strict=True))
            k = 0
            for name in self.curves.names:
                out[name] = pred[k : k + sizes[name]]
                k += sizes[name]
        for j, s in enumerate(self.sections):
            if s not in out:
                out[s] = self._cal_nodes[j]
        for s, q in out.items():
            q = q + shift
            out[s] = self._sim.apply(q) if self.head_frame == "register" else q
        return out

    def _reset_sections(self, names, c, shift, rest: bool = True) -> None:
        """Put the sections ``names`` where the model predicts them (see
        :meth:`_predicted_sections`); ``rest``: their rest lengths too (a lost contour
        re-initialised), else only their nodes (the second pass from the first estimate)."""
        pred = self._predicted_sections(c, shift)
        off = self.contours.offsets
        for j, s in enumerate(self.sections):
            if s not in names:
                continue
            if rest:
                self.snakes.reset_contour(j, pred[s])
            else:
                self.snakes.contours.nodes[off[j] : off[j + 1]] = pred[s]

    def _follow_head(self, frame: np.ndarray) -> str | None:
        """Register the head on ``frame`` and carry the contours with it. When the
        registration does not hold the face (:meth:`HeadTracker.lost`), the frame is searched
        for it (:meth:`HeadTracker.search`, then MediaPipe's face mesh when installed); a face
        found again after it was lost gets every contour re-initialised from the model's
        prediction at the new head pose. Returns ``"face_lost"`` when no face holds."""
        head = self.head
        if not self._face_lost:
            sim = head.track(frame)
            if head.lost() is None:
                a, b = sim.relative_to(self._sim)
                self.snakes.transform(a, b)
                self._sim = sim
                return None
        head.current = self._sim
        sim = head.search(frame)
        if sim is None:
            sim = self._detect_head(frame)
        if sim is None:
            head.current = self._sim
            self._face_lost = True
            return "face_lost"
        a, b = sim.relative_to(self._sim)
        self.snakes.transform(a, b)
        self._sim = sim
        if self._face_lost:
            self._face_lost = False
            self._lost = set()
            self._reset_sections(self.sections, self._c_last, np.zeros(2))
        return None

    def _detect_head(self, frame: np.ndarray):
        """The head's similarity from MediaPipe's face mesh on ``frame`` (the model's rigid
        vertices mapped to the detected points, composed with the model's map onto the
        calibration frame), refined by the registration; None without MediaPipe, a face, or
        a registration that holds it."""
        if self._detector is False or self.model.face.n_vertices != 468:
            return None

        if self._detector is None:
            try:
                self._detector = FaceMeshDetector(video=False)
            except MyofaceDependencyError:
                self._detector = False
                return None
        pts = self._detector.detect(frame)
        if pts is None:
            return None
        rigid = rigid_vertices(self.model)
        model_xy = self.model.face.vertices[rigid, :2] * np.array([1.0, -1.0])
        m2, o2 = similarity_affine(model_xy, pts[rigid, :2])
        m1, o1 = self._model_map
        a = m2 @ np.linalg.inv(m1)
        b = o2 - a @ o1
        c = np.asarray(self.head.c)
        t = a @ c + b - c
        start = Similarity(
            float(np.sqrt(abs(np.linalg.det(a)))),
            float(np.arctan2(a[1, 0], a[0, 0])),
            (float(t[0]), float(t[1])),
            tuple(c),
        )
        sim = self.head.track(frame, start)
        return sim if self.head.lost() is None else None

    # ------------------------------------------------------------ measuring
    def _unmeasured(self, index, time_s, why, contours=None, head=None) -> FrameMeasurement:
        """A frame with empty contractions and the reason; ``head`` = (head shift (2,) px,
        iterations, head scale, head rotation rad), unknown (NaN) by default."""
        nan = np.full(len(self.ids), np.nan)
        t, it, s, th = (np.full(2, np.nan), 0, np.nan, np.nan) if head is None else head
        return FrameMeasurement(index, time_s, why, nan, t, contours or {}, it, s, th)

    def _calibrate(self, frame: np.ndarray, index: int, time_s: float) -> FrameMeasurement:
        """The first frame: the contours settle from their initial place, and what they are
        there becomes the neutral reference."""
        self._frame_shape = frame.shape[:2]
        self._c_last = np.zeros(len(self.ids))  # the neutral frame, until it is measured
        if self.head_frame == "register":
            self.head = HeadTracker(frame, head_box(self._init, np.shape(frame)))
            self._sim = self.head.current
        res, fld = self._relax(frame, None)
        if "mouth" in self._layer_kinds:
            # the lips' tone where the contours settled, and the mouth's sections settled again
            # in their layer raised to it
            band = tuple(b / _init_mm_per_px(self.model, self._init) for b in MOUTH_BAND_MM)
            tones = [
                lips_tone(frame, q, band)
                for s, q in zip(self.sections, res.split(), strict=True)
                if s in self.mouth_sections
            ]
            self.mouth_floor = float(min(tones))
            if np.ndim(frame) == 3 and self.mouth_colour:
                self.mouth_floor = self._mouth_tones(frame, res.split(), band)
            res, fld = self._relax(frame, None)
        self._contrast0 = _contrast(fld)
        conts = res.split()
        pts, ref = self._features(conts)
        self._p0, self._ref0 = pts, ref
        self._calibration_index = index
        self._cal_nodes = [q.copy() for q in conts]
        model_xy = self.estimator.positions(self.model.face.vertices)
        rms_mm = np.sqrt(((model_xy - model_xy.mean(0)) ** 2).sum(1).mean())
        rms_px = np.sqrt(((pts - pts.mean(0)) ** 2).sum(1).mean())
        if rms_px < 5:
            raise MyofaceValueError("the initial contours are too small (under 5 px)")
        self.mm_per_px = rms_mm / rms_px
        # the model (image-like mm) onto the calibration frame (px)
        self._model_map = similarity_affine(model_xy * np.array([1.0, -1.0]), pts)
        named = dict(zip(self.sections, conts, strict=True))
        if self.curves is not None:
            self.curves.calibrate(named, *self._model_map)
            self.mm_per_px = self.curves.mm_per_px
            if self.synthesis_camera is not None:
                self._start_synthesis(frame, conts)
        head_t = np.asarray(self._sim.t, dtype=np.float64)
        hs = (head_t, res.iterations, self._sim.s, self._sim.theta)
        bad = self._escaped(res)
        self._lost = set(bad)
        if bad:
            return self._unmeasured(index, time_s, "escaped:" + "+".join(bad), named, hs)
        if self.curves is None:
            c = self.estimator.estimate(np.zeros_like(pts), refine=self.refine)
        else:
            c = self._fit_curves(conts, np.zeros(2))
        if np.isfinite(c).all():
            self._c_last = c
        return FrameMeasurement(index, time_s, "ok", c, hs[0], named, *hs[1:])

    def measure(self, frame: np.ndarray, index: int = 0, time_s: float = 0.0) -> FrameMeasurement:
        """Track the contours into ``frame`` and estimate its contractions. The first frame
        measured is the neutral calibration frame.

        A frame that cannot be measured gets empty (NaN) contractions and says why in
        ``quality``: ``face_lost`` (the head registration lost the face and no search found
        it; the contours wait where they were), ``low_contrast``, ``escaped:<sections>``
        (more than :data:`ESCAPE_LIMIT` of a contour's nodes off its edge or out of the
        frame), ``misfit:<sections>`` (a contour farther than :data:`MISFIT_MM` from any
        shape the model can take: e.g. on an occluding hand), ``head_turned`` (turned about
        the vertical from the calibration frame's pose past
        :data:`HEAD_TURN_FORESHORTENING`), ``no_fit`` (no contour left to fit the model to).
        Lost sections are re-initialised from the model's prediction at the current head pose
        (the first estimate's, or the last measured frame's); a face found again, from the
        calibration contours mapped by its new pose."""
        frame = np.asarray(frame)
        if self._p0 is None:
            return self._calibrate(frame, index, time_s)
        if frame.shape[:2] != self._frame_shape:
            raise MyofaceValueError(
                f"frame {index} is {frame.shape[1]}x{frame.shape[0]} px; the calibration frame "
                f"was {self._frame_shape[1]}x{self._frame_shape[0]}"
            )
        self._field = None
        if self.head_frame == "register":
            why = self._follow_head(frame)
            if why is not None:
                return self._unmeasured(index, time_s, why)
        if self._lost:
            self._reset_sections(self._lost, self._c_last, self._shift)
        res, fld = self._relax(frame, None)
        low = _contrast(fld) < LOW_CONTRAST * self._contrast0
        bad = self._escaped(res)
        conts_cal = self._to_calibration(res.split())
        shift = self._head_shift(conts_cal)
        if self.curves is not None and self.reseed and not low:
            # analysis by synthesis: put the contours where the model, at a first estimate
            # from the sections that held, says the skin went (lost sections too), let them
            # settle on the frame's edges again and re-estimate. A contour that stopped on a
            # nearer edge (the lower lip on the mouth's inner edge as the jaw drops) is moved
            # past it.
            held = {
                s: q - shift for s, q in zip(self.sections, conts_cal, strict=True) if s not in bad
            }
            # (two rounds: it only has to bring the contours near their features)
            c1 = self.curves.estimate(held, refine=0, rounds=2) if held else self._c_last
            if not np.isfinite(c1).all():
                c1 = self._c_last
            # (the expression did not change since the last frame measured, and every contour
            # held: they are where the model puts them, tracked from there)
            still = not bad and np.abs(c1 - self._c_last).max() < RESEED_STEP
            if not still:
                self._reset_sections(self.curves.names, c1, shift, rest=False)
                self._reset_sections([s for s in bad if s not in self.curves.names], c1, shift)
                res, fld = self._relax(frame, fld)
                bad = self._escaped(res)
                conts_cal = self._to_calibration(res.split())
        elif bad and not low:
            self._reset_sections(bad, self._c_last, shift)
            res, fld = self._relax(frame, fld)
            bad = self._escaped(res)
            conts_cal = self._to_calibration(res.split())
        self._shift = shift
        named = dict(zip(self.sections, res.split(), strict=True))
        head_t = (
            np.asarray(self._sim.t, dtype=np.float64) if self.head_frame == "register" else shift
        )
        hs = (head_t, res.iterations, self._sim.s, self._sim.theta)
        self._lost = set(bad)
        if low:
            return self._unmeasured(index, time_s, "low_contrast", named, hs)
        if bad:
            return self._unmeasured(index, time_s, "escaped:" + "+".join(bad), named, hs)
        if self.curves is None:
            pts, _ = self._features(conts_cal)
            d_mm = (pts - self._p0 - shift) * self.mm_per_px * np.array([1.0, -1.0])
            c = self.estimator.estimate(d_mm, refine=self.refine)
        else:
            cal = {s: q - shift for s, q in zip(self.sections, conts_cal, strict=True)}
            deferred = self.deferred_relax and self._synth is None
            c = self.curves.estimate(cal, refine=self.refine, deferred=deferred)
            resid = self.curves.last_residuals
            misfit = [s for s, r in resid.items() if r > MISFIT_MM]
            self.last_residuals_mm = resid
            if misfit:
                self._lost = set(misfit)
                return self._unmeasured(index, time_s, "misfit:" + "+".join(misfit), named, hs)
        if self.head_frame == "register" and self.head.foreshortening < HEAD_TURN_FORESHORTENING:
            return self._unmeasured(index, time_s, "head_turned", named, hs)
        if self._synth is not None:
            c = self._by_synthesis(c, conts_cal, shift)
        if not np.isfinite(c).all():  # no contour the model could be fitted to
            return self._unmeasured(index, time_s, "no_fit", named, hs)
        self._c_last = c
        return FrameMeasurement(index, time_s, "ok", c, hs[0], named, *hs[1:])

    # ------------------------------------------------------------ analysis by synthesis
    def _track_synthetic(self, skin: np.ndarray, start: list[np.ndarray], jaw=None) -> dict:
        """The contours tracked on the model rendered at ``skin`` (the lower teeth moved by the
        jaw's rigid motion ``jaw``, None: closed), from the nodes ``start`` (calibration
        coordinates), with the video tracker's rest lengths and parameters."""
        sn = self._synth_snakes
        sn.contours.nodes[:] = np.concatenate(start)
        sn.rest[:] = self.snakes.rest / (self._sim.s if self.head_frame == "register" else 1.0)
        sn.reference = self.snakes.reference
        fld = self._field_for(self._synth.render(skin, jaw), sn.contours.nodes)
        return dict(zip(self.sections, sn.relax(fld).split(), strict=True))

    def _start_synthesis(self, frame: np.ndarray, conts_cal: list[np.ndarray]) -> None:
        self._synth = FrameSynthesizer(
            self.model.face, self.synthesis_camera, frame, teeth=self.synthesis_teeth
        )
        self._synth_snakes = Snakes(self.contours, self.params, layers=self.layers)
        rest = self._track_synthetic(self.model.face.vertices, conts_cal)
        _, self._synth_bias, _ = self.curves.residuals(rest, self.curves.p0)

    def _by_synthesis(self, c: np.ndarray, conts_cal: list[np.ndarray], shift) -> np.ndarray:
        start = [q - shift for q in conts_cal]
        video = dict(zip(self.sections, start, strict=True))
        for _ in range(self.synthesis_rounds):
            skin = self.curves.relaxed_skin(c)
            synth = self._track_synthetic(skin, start, self.model.jaw_pose(self.curves.state))
            pred = self.curves.predicted(skin)
            self.curves.relinearise(c, pred)
            c = self.curves.synthesis_step(c, pred, video, synth, self._synth_bias)
        return c

    def close(self) -> None:
        """Stop the curve fit's relax thread, and release the face detector if a lost face
        was searched for with it."""
        if self.curves is not None:
            self.curves.close()
        if self._detector:
            self._detector.close()
        self._detector = None


def _ellipse(q: np.ndarray) -> tuple:
    """(cx, cy, ax, ay): the centre and half extents (px, at least 1) of the points ``q``."""
    lo, hi = q.min(axis=0), q.max(axis=0)
    c, half = 0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 1.0)
    return (float(c[0]), float(c[1]), float(half[0]), float(half[1]))


def _contrast(fld: PotentialField) -> float:
    """The strongest edges of a frame: the 99th percentile of -P (first layer) in the
    window."""
    v = -fld.potential[0].ravel()
    k = int(0.99 * (len(v) - 1))
    return float(np.partition(v, k)[k])


class SnakeTracker(TrackerBase):
    """The snakes (:class:`Analyzer`) behind the trackers' protocol.

    Parameters
    ----------
    model : FaceModel (never changed).
    init : {section: (K, 2)} initial contours on the first frame it is given (the
        calibration frame), or None: found with MediaPipe's face mesh on the first frame
        with a face (:func:`~myoface.analysis.landmarks.auto_init`).
    show_progress : a progress bar while a face is searched for; ``total`` the frames there
        are to search (for the bar).
    analyzer_options : :class:`Analyzer`'s (``refine``, ``sigma``, ``estimator``,
        ``deferred_relax``, ...).
    """

    def __init__(self, model, init=None, *, show_progress: bool = False,
                 total: int | None = None, **analyzer_options):  # fmt: skip
        self.model = model
        self.ids = tuple(analyzer_options.get("muscle_ids") or PAPER_MUSCLES)
        self._init = init
        self._show_progress = bool(show_progress)
        self._total = total
        self._options = analyzer_options
        self.analyzer: Analyzer | None = None
        self.how = "contours given"
        self.start: int | None = None

    def calibrate(self, frames, first_index: int = 0) -> int:
        """The initial contours (given, or MediaPipe's on the first frame with a face; a
        clear error when they leave the frame); returns that frame's position in
        ``frames``."""
        frames = iter(frames)
        init, k = self._init, 0
        if init is None:
            k, frame, init, _ = auto_init(
                frames, self.model.face, show_progress=self._show_progress, total=self._total
            )
            self.how = f"automatic: MediaPipe face mesh on frame {first_index + k}"
            size = np.shape(frame)
        else:
            frame = next(frames, None)
            if frame is None:
                raise MyofaceValueError("the video has no frames to calibrate on")
            size = np.shape(frame)
        h, w = size[:2]
        for name, pts in init.items():
            pts = np.asarray(pts)
            if (pts < 0).any() or (pts[:, 0] > w - 1).any() or (pts[:, 1] > h - 1).any():
                raise MyofaceValueError(f"contour {name!r} lies outside the frame")
        self.analyzer = Analyzer(self.model, init, **self._options)
        self.ids = tuple(self.analyzer.ids)
        self.start = first_index + k
        return k

    def measure(self, frame, index: int = 0, time_s: float = 0.0, observation=None):
        return self.analyzer.measure(frame, index, time_s)

    def describe(self) -> dict:
        an = self.analyzer
        return {
            "init": self.how,
            "calibration_frame": self.start,
            "mm_per_px": an.mm_per_px,
            "refine": an.refine,
            "sigma_px": an.sigma,
            "estimator": an.method,
            "snake_params": {
                k: float(np.mean(v)) if not isinstance(v, int) else v
                for k, v in vars(an.params).items()
            },
        }

    def debug_images(self, frame, measurement) -> dict:
        """The snakes' potential (the image force field they settle in)."""
        return {"potential": potential_image(self.analyzer.last_potential)}

    def close(self) -> None:
        if self.analyzer is not None:
            self.analyzer.close()
