"""The muscle types of the muscle level and their displacement fields.

Every muscle maps a unit contraction to a displacement of the fascia points it acts on. For a
contraction vector c (M,) the fascia node j moves to ``x_j + sum_i c_i B_i(x_j)`` (Terzopoulos &
Waters 1993, eq. (5)); each ``B_i`` is evaluated once at the rest positions, so contractions
superpose linearly and the muscle basis is a constant (N, 3, M) array (see
:meth:`myoface.muscles.MuscleSet.basis`).

All points are in the head frame (mm): +y up, +z out of the face, the subject's left at +x.

``region`` restricts a muscle to one side of the mouth slit: ``"lower"`` weights its field by the
jaw weight of each point (1 on the lower lip and chin, 0 above the mouth), ``"upper"`` by one
minus it, ``"all"`` not at all. This keeps, e.g., the depressor labii inferioris from dragging
the upper lip, which lies a millimetre away across the slit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceValueError

REGIONS = ("all", "upper", "lower")

#: points closer than this (mm) to a muscle's own origin get no displacement (direction undefined)
MIN_DISTANCE_MM = 1e-9


def _vec3(name: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.isfinite(a).all():
        raise MyofaceValueError(f"{name} must be a finite 3-vector (mm); got {value!r}")
    return a


def _positive(name: str, value: float, allow_zero: bool = False) -> float:
    v = float(value)
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise MyofaceValueError(f"{name} must be {'>= 0' if allow_zero else '> 0'}; got {value!r}")
    return v


def _check_region(muscle_id: str, region: str) -> None:
    if region not in REGIONS:
        raise MyofaceValueError(
            f"region of muscle {muscle_id!r} must be one of {REGIONS}; got {region!r}"
        )


def region_weight(region: str, lower: np.ndarray) -> np.ndarray:
    """Multiplier (N,) of a muscle field for points with jaw weights ``lower`` (N,) in [0, 1]."""
    if region == "lower":
        return lower
    if region == "upper":
        return 1.0 - lower
    return np.ones_like(lower)


def cosine_falloff(d: np.ndarray, radius: float) -> np.ndarray:
    """``cos(d / radius * pi/2)`` inside ``d <= radius``, 0 outside (T&W 1993, eq. (6))."""
    out = np.cos(np.clip(d / radius, 0.0, 1.0) * (np.pi / 2))
    out[d > radius] = 0.0
    return out


@dataclass(frozen=True)
class LinearMuscle:
    """A linear muscle with the paper's cosine blend (T&W 1993, eq. (5)-(6)).

    Parameters
    ----------
    id : str — anatomical, side-suffixed id, e.g. ``"zygomaticus_major_l"``.
    origin : (3,) mm — emergence point m^e in bone.
    insertion : (3,) mm — attachment point m^a at the fascia.
    radius_mm : float — radius of influence r_i around the insertion.
    max_shortening_mm : float
        Length of the displacement at c = 1 where b_ij = 1. Eq. (5) moves a node by the whole
        muscle vector m_i = m^e - m^a at c = 1 (to the bone); we scale m_i to this length so that
        c in [0, 1] spans a physiological range (a muscle shortens by about a third of its length).
    region : {"all", "upper", "lower"}
    lower_share : float in [0, 1]
        The share of the field the lower lip and chin (jaw weight 1) take: the field is weighted
        by ``1 - (1 - lower_share) * lower``, so the mouth corner (jaw weight 1/2 on the slit)
        keeps more of it than the lower lip beyond. Default 1 (eq. (6) unweighted). For a
        muscle inserting into the modiolus, which moves the lower lip only through the lip's
        own fibres: the zygomatic major.
    """

    id: str
    origin: np.ndarray
    insertion: np.ndarray
    radius_mm: float
    max_shortening_mm: float
    region: str = "all"
    lower_share: float = 1.0
    kind = "linear"

    def __post_init__(self):
        object.__setattr__(self, "origin", _vec3(f"origin of {self.id}", self.origin))
        object.__setattr__(self, "insertion", _vec3(f"insertion of {self.id}", self.insertion))
        _positive(f"radius_mm of {self.id}", self.radius_mm)
        _positive(f"max_shortening_mm of {self.id}", self.max_shortening_mm, allow_zero=True)
        _check_region(self.id, self.region)
        share = float(self.lower_share)
        if not 0.0 <= share <= 1.0:
            raise MyofaceValueError(f"lower_share of {self.id} must be in [0, 1]; got {share!r}")
        object.__setattr__(self, "lower_share", share)
        if np.linalg.norm(self.origin - self.insertion) < 1e-6:
            raise MyofaceValueError(f"muscle {self.id!r}: origin and insertion coincide")

    @property
    def direction(self) -> np.ndarray:
        """Unit vector of the muscle, from the insertion towards the origin."""
        m = self.origin - self.insertion
        return m / np.linalg.norm(m)

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) mm of ``points`` (N, 3) per unit contraction."""
        d = np.linalg.norm(self.insertion - points, axis=1)
        b = cosine_falloff(d, self.radius_mm) * region_weight(self.region, lower)
        if self.lower_share < 1.0:
            b = b * (1.0 - (1.0 - self.lower_share) * lower)
        return b[:, None] * (self.max_shortening_mm * self.direction)[None, :]

    def mirrored(self, new_id: str) -> LinearMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        return LinearMuscle(
            new_id,
            self.origin * f,
            self.insertion * f,
            self.radius_mm,
            self.max_shortening_mm,
            self.region,
            self.lower_share,
        )


@dataclass(frozen=True)
class WatersMuscle:
    """Waters' (1987) linear muscle with an angular zone and a radial cosine fall-off.

    A point p inside the cone of half-angle ``zone_deg`` around the axis from the bone point
    towards the skin point, and within ``fall_end_mm`` of the bone point, moves towards the bone
    point by ``v (cos(a)/cos(zone) - 1) R(|p - bone|) (bone - p)``, where a is the angle between
    p - bone and the axis, R = 1 inside ``fall_start_mm`` and ``cos((d - start)/(end - start) *
    pi/2)`` between the two radii, and v = c * ``clamp`` (Waters' contraction value; his data
    give each muscle's largest value as its "clamp", so c = 1 is that value).

    References: K. Waters, "A muscle model for animating three-dimensional facial expression",
    SIGGRAPH 1987; Parke & Waters, *Computer Facial Animation*, appendix (``muscle.c``).
    """

    id: str
    skin_point: np.ndarray
    bone_point: np.ndarray
    fall_start_mm: float
    fall_end_mm: float
    zone_deg: float
    clamp: float
    region: str = "all"
    source_name: str = ""
    kind = "waters"

    def __post_init__(self):
        object.__setattr__(self, "skin_point", _vec3(f"skin point of {self.id}", self.skin_point))
        object.__setattr__(self, "bone_point", _vec3(f"bone point of {self.id}", self.bone_point))
        _positive(f"fall_start_mm of {self.id}", self.fall_start_mm, allow_zero=True)
        _positive(f"fall_end_mm of {self.id}", self.fall_end_mm)
        if self.fall_end_mm <= self.fall_start_mm:
            raise MyofaceValueError(f"muscle {self.id!r}: fall-off end must exceed its start")
        if not 0 < float(self.zone_deg) < 90:
            raise MyofaceValueError(
                f"zone angle of muscle {self.id!r} must be in (0, 90) degrees; got {self.zone_deg}"
            )
        _positive(f"clamp of {self.id}", self.clamp)
        _check_region(self.id, self.region)

    @property
    def origin(self) -> np.ndarray:
        return self.bone_point

    @property
    def insertion(self) -> np.ndarray:
        return self.skin_point

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        axis = self.skin_point - self.bone_point
        axis = axis / np.linalg.norm(axis)
        vb = points - self.bone_point
        d = np.linalg.norm(vb, axis=1)
        cos_a = (vb @ axis) / np.maximum(d, MIN_DISTANCE_MM)
        cos_zone = np.cos(np.deg2rad(self.zone_deg))
        angular = np.where(cos_a >= cos_zone, cos_a / cos_zone - 1.0, 0.0)
        span = self.fall_end_mm - self.fall_start_mm
        radial = np.where(
            d <= self.fall_start_mm,
            1.0,
            np.cos(np.clip((d - self.fall_start_mm) / span, 0, 1) * np.pi / 2),
        )
        radial[d > self.fall_end_mm] = 0.0
        w = self.clamp * angular * radial * region_weight(self.region, lower)
        w[d < MIN_DISTANCE_MM] = 0.0
        return -w[:, None] * vb

    def mirrored(self, new_id: str) -> WatersMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        return WatersMuscle(
            new_id,
            self.skin_point * f,
            self.bone_point * f,
            self.fall_start_mm,
            self.fall_end_mm,
            self.zone_deg,
            self.clamp,
            self.region,
            self.source_name,
        )


@dataclass(frozen=True)
class SheetMuscle:
    """A sheet muscle: parallel fibres over a strip, e.g. a belly of the frontalis.

    The strip runs from the insertion line (centre ``insertion``, in the skin of the brow) towards
    its origin (``origin``, the galea / bone at the top of the forehead), ``width_mm`` wide. A
    point at distance s along the fibres from the insertion line and t across them moves along
    the fibre direction (towards the origin) by ``max_shortening_mm * A(s) * B(t)``, with
    ``A = cos(s / L * pi/2)`` above the line (L = distance insertion-origin), ``A = cos(-s / below_mm *
    pi/2)`` below it (the brow skin the fibres pull on), and ``B = cos(t / (width/2) * pi/2)``.

    The paper names sheet muscles (occipitofrontalis) as a type without giving their field; this
    is our design, a broad version of eq. (6).
    """

    id: str
    origin: np.ndarray
    insertion: np.ndarray
    width_mm: float
    below_mm: float
    max_shortening_mm: float
    normal: np.ndarray
    region: str = "all"
    kind = "sheet"

    def __post_init__(self):
        object.__setattr__(self, "origin", _vec3(f"origin of {self.id}", self.origin))
        object.__setattr__(self, "insertion", _vec3(f"insertion of {self.id}", self.insertion))
        n = _vec3(f"normal of {self.id}", self.normal)
        object.__setattr__(self, "normal", n / max(np.linalg.norm(n), MIN_DISTANCE_MM))
        _positive(f"width_mm of {self.id}", self.width_mm)
        _positive(f"below_mm of {self.id}", self.below_mm)
        _positive(f"max_shortening_mm of {self.id}", self.max_shortening_mm, allow_zero=True)
        _check_region(self.id, self.region)

    @property
    def direction(self) -> np.ndarray:
        """Fibre direction: towards the origin, in the tangent plane of the skin at the insertion
        (a sheet lies flat under the skin, which slides along it rather than into the bone)."""
        m = self.origin - self.insertion
        m = m - (m @ self.normal) * self.normal
        return m / np.linalg.norm(m)

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        d = self.direction
        across = np.cross(d, self.normal)
        across /= np.linalg.norm(across)
        rel = points - self.insertion
        s = rel @ d
        t = np.abs(rel @ across)
        length = float(np.linalg.norm(self.origin - self.insertion))
        a = np.where(
            s >= 0,
            np.cos(np.clip(s / length, 0, 1) * np.pi / 2),
            np.cos(np.clip(-s / self.below_mm, 0, 1) * np.pi / 2),
        )
        b = cosine_falloff(t, 0.5 * self.width_mm)
        w = a * b * region_weight(self.region, lower)
        return w[:, None] * (self.max_shortening_mm * d)[None, :]

    def mirrored(self, new_id: str) -> SheetMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        return SheetMuscle(
            new_id,
            self.origin * f,
            self.insertion * f,
            self.width_mm,
            self.below_mm,
            self.max_shortening_mm,
            self.normal * f,
            self.region,
        )


@dataclass(frozen=True)
class SphincterMuscle:
    """A sphincter muscle: a ring around an orifice drawing towards a virtual centre.

    With ``u`` and ``v`` the in-plane offsets of a point from ``center`` along the ring's axes
    (``axis_u``, and ``normal x axis_u``), the elliptic radius is ``rho = sqrt((u/a)^2 + (v/b)^2)``
    for the semi-axes ``a, b = semi_axes_mm``. The ring (rho = 1) moves the most; the weight is
    ``sin(rho * pi/2)`` inside and ``cos((rho - 1) / falloff * pi/2)`` outside, zero beyond
    ``1 + falloff``. A point moves towards the centre (in the ring's plane) by
    ``max_contraction_mm * weight``, and along ``normal`` by ``protrusion_mm * weight`` (the lips
    purse forwards).

    References: T&W 1993, Section III-C names the type; the elliptic ring follows Waters'
    sphincter (Parke & Waters, *Computer Facial Animation*, ch. 7). The exact weight is ours.
    """

    id: str
    center: np.ndarray
    normal: np.ndarray
    axis_u: np.ndarray
    semi_axes_mm: tuple[float, float]
    falloff: float
    max_contraction_mm: float
    protrusion_mm: float = 0.0
    region: str = "all"
    kind = "sphincter"

    def __post_init__(self):
        object.__setattr__(self, "center", _vec3(f"center of {self.id}", self.center))
        n = _vec3(f"normal of {self.id}", self.normal)
        n = n / max(np.linalg.norm(n), MIN_DISTANCE_MM)
        u = _vec3(f"axis_u of {self.id}", self.axis_u)
        u = u - (u @ n) * n
        if np.linalg.norm(u) < 1e-6:
            raise MyofaceValueError(f"muscle {self.id!r}: axis_u must not be parallel to normal")
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "axis_u", u / np.linalg.norm(u))
        a, b = (float(x) for x in self.semi_axes_mm)
        _positive(f"semi-axes of {self.id}", a)
        _positive(f"semi-axes of {self.id}", b)
        object.__setattr__(self, "semi_axes_mm", (a, b))
        _positive(f"falloff of {self.id}", self.falloff)
        _positive(f"max_contraction_mm of {self.id}", self.max_contraction_mm, allow_zero=True)
        _positive(f"protrusion_mm of {self.id}", self.protrusion_mm, allow_zero=True)
        _check_region(self.id, self.region)

    @property
    def origin(self) -> np.ndarray:
        return self.center

    @property
    def insertion(self) -> np.ndarray:
        return self.center + self.semi_axes_mm[0] * self.axis_u

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        axis_v = np.cross(self.normal, self.axis_u)
        rel = points - self.center
        u = rel @ self.axis_u
        v = rel @ axis_v
        a, b = self.semi_axes_mm
        rho = np.sqrt((u / a) ** 2 + (v / b) ** 2)
        w = np.where(
            rho <= 1.0,
            np.sin(np.clip(rho, 0, 1) * np.pi / 2),
            np.cos(np.clip((rho - 1.0) / self.falloff, 0, 1) * np.pi / 2),
        )
        w[rho > 1.0 + self.falloff] = 0.0
        w = w * region_weight(self.region, lower)
        inplane = u[:, None] * self.axis_u[None, :] + v[:, None] * axis_v[None, :]
        norm = np.linalg.norm(inplane, axis=1, keepdims=True)
        towards = -inplane / np.maximum(norm, MIN_DISTANCE_MM)
        return w[:, None] * (
            self.max_contraction_mm * towards + self.protrusion_mm * self.normal[None, :]
        )

    def mirrored(self, new_id: str) -> SphincterMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        return SphincterMuscle(
            new_id,
            self.center * f,
            self.normal * f,
            self.axis_u * f,
            self.semi_axes_mm,
            self.falloff,
            self.max_contraction_mm,
            self.protrusion_mm,
            self.region,
        )


@dataclass(frozen=True)
class PterygoidMuscle:
    """A lateral pterygoid: it moves the mandible (the bone layer), not the fascia.

    Contracted alone, a lateral pterygoid pulls its own condyle forward and in, down the
    articular eminence, and the mandible swings about the other condyle: the chin goes to the
    opposite side (FACS AD30, jaw sideways). Both together bring the jaw forward (AU29, jaw
    thrust). Its field is the mandible's turn about a vertical axis through the opposite
    condyle, linear in the contraction (T&W 1993, eq. (5): contractions superpose), and weighted
    per point by the jaw's following weight (1 on the chin and lower lip, 0 above the mouth).
    The turn is ``max_travel_mm`` at the ``reference`` point (the chin) at full contraction.
    :class:`myoface.model.FaceModel` applies it to the bone nodes only, so the skin follows the
    bone through the tissue as it does the jaw's opening, and the lower teeth follow it
    (:meth:`myoface.model.FaceModel.jaw_pose`).

    Parameters
    ----------
    id : str — e.g. ``"lateral_pterygoid_l"``.
    origin : (3,) mm — the lateral pterygoid plate (for overlays: the muscle's line).
    insertion : (3,) mm — the neck of its own condyle.
    reference : (3,) mm — where the travel is given (the chin).
    max_travel_mm : float — the reference point's travel at contraction 1.
    pivot : (3,) mm, optional — the opposite condyle, about which the mandible turns (default:
        the insertion mirrored in x, for a face centred on x = 0).
    """

    id: str
    origin: np.ndarray
    insertion: np.ndarray
    reference: np.ndarray
    max_travel_mm: float
    pivot: np.ndarray | None = None
    kind = "pterygoid"
    region = "lower"
    #: what the muscle moves: the bone layer (see :class:`myoface.model.FaceModel`)
    acts_on = "bone"

    def __post_init__(self):
        for name in ("origin", "insertion", "reference"):
            object.__setattr__(self, name, _vec3(f"{name} of {self.id}", getattr(self, name)))
        pivot = self.insertion * np.array([-1.0, 1.0, 1.0]) if self.pivot is None else self.pivot
        object.__setattr__(self, "pivot", _vec3(f"pivot of {self.id}", pivot))
        _positive(f"max_travel_mm of {self.id}", self.max_travel_mm)
        arm = np.cross([0.0, 1.0, 0.0], self.reference - self.pivot)
        if np.linalg.norm(arm) < 1.0 or np.linalg.norm(self.insertion - self.pivot) < 1.0:
            raise MyofaceValueError(
                f"muscle {self.id!r}: the reference and the insertion must lie away from the "
                "pivot's vertical axis"
            )
        if np.linalg.norm(self.origin - self.insertion) < 1e-6:
            raise MyofaceValueError(f"muscle {self.id!r}: origin and insertion coincide")

    @property
    def turn_rad(self) -> float:
        """The mandible's signed turn about +y at contraction 1: the sign that brings the
        insertion (its condyle) towards the origin."""
        up = np.array([0.0, 1.0, 0.0])
        arm = np.linalg.norm(np.cross(up, self.reference - self.pivot))
        pull = np.cross(up, self.insertion - self.pivot) @ (self.origin - self.insertion)
        return float(np.sign(pull) or 1.0) * self.max_travel_mm / arm

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) mm of ``points`` (N, 3) per unit contraction: the linearised
        turn about the pivot's vertical axis, times each point's jaw weight ``lower``."""
        p = np.asarray(points, dtype=np.float64)
        d = np.cross([0.0, self.turn_rad, 0.0], p - self.pivot)
        return np.asarray(lower, dtype=np.float64)[:, None] * d

    def mirrored(self, new_id: str) -> PterygoidMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        return PterygoidMuscle(
            new_id,
            self.origin * f,
            self.insertion * f,
            self.reference * f,
            self.max_travel_mm,
            self.pivot * f,
        )


Muscle = LinearMuscle | WatersMuscle | SheetMuscle | SphincterMuscle | PterygoidMuscle
