"""Eyelids: the skin around each eye opening moved over the eyeball by the lid muscles.

Two actuators per eye, in the contraction vector like every muscle:

- ``levator_palpebrae_superioris_<side>`` (action ``"raise"``, FACS AU5): raises the upper lid;
  its relaxation (0) leaves the lid where the tissue put it;
- ``orbicularis_oculi_palpebralis_<side>`` (action ``"close"``, AU7 lid tightener, AU43 eyes
  closed, AU45 blink): brings the upper lid down and the lower lid up to meet; at 1 the margins
  meet along their whole length.

The pars orbitalis (AU6, the cheek raiser) stays the tissue's sphincter ``orbicularis_oculi``:
it raises the lower lid and the cheek through the tissue; the lids then keep it from pushing the
lower lid over the upper one (see below).

How the lids move
-----------------
The lids are skin, not tissue nodes: they are placed on the tissue's relaxed skin (as the teeth
keep the lips out, :meth:`myoface.model.FaceModel.skin_vertices`), so the tissue, its solver and
the analysis' responses are unchanged and a state stays a value. Around each eye, in cylindrical
coordinates about the eyeball centre's horizontal (x) axis, a point is (x, rho, phi) with
``phi = atan2(y - c_y, z - c_z)`` its elevation. The margin of the opening splits at the canthi
(its ends in x) into an upper and a lower chain; each margin vertex has a parameter s, its rest
x, and sees the opposite lid at the same s (linear interpolation along the opposite chain, the
canthi at the ends). With the gap ``g = phi_upper - phi_lower`` at s, the lids meet at
``phi_m = phi_lower + LOWER_SHARE g`` (x and rho likewise), and with closure ``k`` (the
palpebral contraction) every margin coordinate q moves to ``q_m + (1 - k) (q - q_m)``; the
levator adds to the upper margin a rotation of ``angle_deg`` times its contraction, scaled along
the lid by the rest gap (the lid's arc is kept) and times ``1 - k`` (closing wins). Margins
closer than :data:`TOUCH_RAD` in angle count as closing (the lids touch and stay together), and
margins the tissue has crossed meet half way: the upper lid never passes below the lower one.

Before that, the lids slide on the eyeball: every lid vertex is brought back towards its rest
distance from the eyeball centre (fully on the margin, by its weight around it), and the upper lid
keeps only ``1 - UPPER_HOLD`` of the tissue's rotation of it about the eyeball's axis (its tarsus
hangs from the levator: a brow raise lifts the skin above the lid, not the margin, so AU1+2
alone does not open the eye as AU5 does, and the two stay apart for the analysis).

Skin around the margins follows its lid: a vertex within :data:`UPPER_FALLOFF_MM` (upper lid) or
:data:`LOWER_FALLOFF_MM` (lower lid) of its margin rotates about the eyeball's axis by the
margin's rotation at its x times a raised-cosine weight of that distance. A rotation about an
axis through the eyeball centre keeps every point's distance to it, and the margins move between
points outside the eyeball; finally every lid vertex closer than :data:`CONTACT_MM` to the
eyeball (the tissue can push skin there) is moved out along the ray from the centre: the lids
never pass through the eyeball.

References: Terzopoulos & Waters 1993, Section III (kinematic parts beside the tissue, as the
jaw); Ekman, Friesen & Hager, Facial Action Coding System: The Manual (2002), AU5, AU7, AU43,
AU45 (their muscular basis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.face.eyes import EYE_RADIUS_MM, eye_loop, eyeball_center

LID_ACTIONS = ("raise", "close")
#: where the margins meet, as a fraction of the gap above the lower margin: in a blink the
#: upper lid does nearly all of the travel and the lower lid rises a little (our choice)
LOWER_SHARE = 0.2
#: skin up to this distance (mm) from the upper margin follows the upper lid (the upper tarsal
#: plate is about 10 mm high; Gray's Anatomy, 41st ed., ch. "Orbit")
UPPER_FALLOFF_MM = 9.0
#: ... and from the lower margin the lower lid (the lower tarsal plate: about 4-5 mm, ibid.)
LOWER_FALLOFF_MM = 5.0
#: margins nearer than this in elevation (rad, about 1.5 degrees: 0.3 mm at the margin's 12 mm
#: from the eyeball's axis) are touching: drawn together, so a nearly closed eye closes
TOUCH_RAD = np.deg2rad(1.5)
#: the share of the tissue's rotation of the upper lid about the eyeball that the lid does not
#: follow: its tarsus hangs from the levator, which holds it, so a brow raise lifts the lid skin
#: above it but the margin little (our choice)
UPPER_HOLD = 0.7
#: the least distance (mm) a lid vertex keeps from the eyeball's surface under contact
CONTACT_MM = 0.25


@dataclass(frozen=True)
class LidMuscle:
    """A lid actuator: it moves the skin of the eyelids directly (no tissue field).

    Parameters
    ----------
    id : str — e.g. ``"levator_palpebrae_superioris_l"``.
    eye : str — the landmark group of its eye opening (``"eye_l"``).
    action : {"raise", "close"} — levator palpebrae superioris / orbicularis oculi pars
        palpebralis.
    origin, insertion : (3,) mm — where the muscle runs (for drawing; the lid motion does not
        use them).
    angle_deg : float — ``"raise"``: the upper margin's rotation about the eyeball's axis at
        contraction 1 where the lids are farthest apart (degrees).
    """

    id: str
    eye: str
    action: str
    origin: np.ndarray
    insertion: np.ndarray
    angle_deg: float = 0.0
    region: str = "all"
    kind = "lid"

    def __post_init__(self):
        if self.action not in LID_ACTIONS:
            raise MyofaceValueError(
                f"action of lid muscle {self.id!r} must be one of {LID_ACTIONS}; got {self.action!r}"
            )
        a = float(self.angle_deg)
        if not np.isfinite(a) or not 0.0 <= a <= 45.0:
            raise MyofaceValueError(
                f"angle_deg of lid muscle {self.id!r} must be in [0, 45]; got {self.angle_deg!r}"
            )
        for name in ("origin", "insertion"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (3,) or not np.isfinite(v).all():
                raise MyofaceValueError(f"{name} of {self.id} must be a finite 3-vector (mm)")
            object.__setattr__(self, name, v)

    def field(self, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """Zero (N, 3): a lid muscle does not drive the tissue (see the module doc)."""
        return np.zeros((len(points), 3))

    def mirrored(self, new_id: str) -> LidMuscle:
        f = np.array([-1.0, 1.0, 1.0])
        eye = self.eye
        if eye.endswith("_l") or eye.endswith("_r"):
            eye = eye[:-2] + ("_r" if eye.endswith("_l") else "_l")
        return LidMuscle(
            new_id, eye, self.action, self.origin * f, self.insertion * f, self.angle_deg
        )


def _cylindrical(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N, 3) points -> (N, 3) (x, rho, phi) about the x-axis through ``c``."""
    q = p - c
    return np.column_stack([q[:, 0], np.hypot(q[:, 1], q[:, 2]), np.arctan2(q[:, 1], q[:, 2])])


def _cartesian(q: np.ndarray, c: np.ndarray) -> np.ndarray:
    return c + np.column_stack([q[:, 0], q[:, 1] * np.sin(q[:, 2]), q[:, 1] * np.cos(q[:, 2])])


def _falloff(d: np.ndarray, radius: float) -> np.ndarray:
    return np.where(d < radius, 0.5 + 0.5 * np.cos(np.pi * np.clip(d / radius, 0, 1)), 0.0)


class _Eye:
    """The fixed geometry of one eye: chains, parameters, surrounding skin and weights."""

    def __init__(self, rest: np.ndarray, loop: np.ndarray, raise_i, close_i, raise_rad):
        self.center = eyeball_center(rest, loop)
        self.raise_i, self.close_i, self.raise_rad = raise_i, close_i, float(raise_rad)
        x = rest[loop, 0]
        a, b = int(np.argmin(x)), int(np.argmax(x))
        n = len(loop)
        one = [loop[(a + k) % n] for k in range(1, (b - a) % n)]
        two = [loop[(b + k) % n] for k in range(1, (a - b) % n)]
        if not one or not two:
            raise MyofaceValueError("an eye opening needs vertices above and below its corners")
        if rest[one, 1].mean() < rest[two, 1].mean():
            one, two = two, one
        self.canthi = np.array([loop[a], loop[b]])

        def ordered(chain):  # by rest x, the canthi at the ends
            chain = np.asarray(chain)
            return np.r_[loop[a], chain[np.argsort(rest[chain, 0], kind="stable")], loop[b]]

        self.upper, self.lower = ordered(one), ordered(two)
        self.s_upper, self.s_lower = rest[self.upper, 0], rest[self.lower, 0]
        rest_cyl = _cylindrical(rest, self.center)
        # the rest gap along the upper chain: the levator raises the lid in this shape
        gap = rest_cyl[self.upper, 2] - np.interp(
            self.s_upper, self.s_lower, rest_cyl[self.lower, 2]
        )
        gap = np.maximum(gap, 0.0)
        self.raise_shape = gap / gap.max() if gap.max() > 0 else gap
        # the skin around: vertices near a margin, on its side of the line through the canthi
        p0, p1 = rest[loop[a]], rest[loop[b]]
        in_loop = np.zeros(len(rest), bool)
        in_loop[loop] = True
        t = np.clip((rest[:, 0] - p0[0]) / (p1[0] - p0[0]), 0.0, 1.0)
        above = rest[:, 1] > p0[1] + t * (p1[1] - p0[1])
        self.rings = {}
        for chain, falloff, is_up in (
            (self.upper, UPPER_FALLOFF_MM, True),
            (self.lower, LOWER_FALLOFF_MM, False),
        ):
            d = np.linalg.norm(rest[:, None, :] - rest[None, chain, :], axis=2).min(axis=1)
            pick = np.flatnonzero((d < falloff) & ~in_loop & (above == is_up))
            # (vertices, their rest x, their weights)
            self.rings[is_up] = (pick, rest[pick, 0], _falloff(d[pick], falloff))
        self.vertices = np.unique(np.r_[loop, self.rings[True][0], self.rings[False][0]])
        # the lids slide on the eyeball: each keeps its rest distance from the centre (the
        # margin fully, the skin around by its weight)
        self.slide = np.r_[loop, self.rings[True][0], self.rings[False][0]]
        self.slide_w = np.r_[np.ones(len(loop)), self.rings[True][2], self.rings[False][2]]
        self.slide_mm = np.linalg.norm(rest[self.slide] - self.center, axis=1)
        up_ring, _, up_w = self.rings[True]
        hold = np.r_[self.upper[1:-1], up_ring]
        self.hold = (hold, np.r_[np.ones(len(self.upper) - 2), up_w])
        self.hold_phi = rest_cyl[hold, 2]

    def apply(self, skin: np.ndarray, contractions: np.ndarray, out: np.ndarray) -> None:
        """Write the lids of ``skin`` (V, 3) mm for ``contractions`` (M,) into ``out``."""
        c = self.center
        lev = float(contractions[self.raise_i]) if self.raise_i is not None else 0.0
        k = float(contractions[self.close_i]) if self.close_i is not None else 0.0
        r = skin[self.slide] - c
        dist = np.linalg.norm(r, axis=1)
        skin = np.array(skin)
        skin[self.slide] = c + r * (1.0 + self.slide_w * (self.slide_mm / dist - 1.0))[:, None]
        cyl = _cylindrical(skin, c)
        if UPPER_HOLD > 0:  # the upper tarsus held by the levator: the tissue moves it less
            idx, w = self.hold
            cyl[idx, 2] -= UPPER_HOLD * w * (cyl[idx, 2] - self.hold_phi)
            skin[idx] = _cartesian(cyl[idx], c)
        out[self.slide] = skin[self.slide]
        chains = {True: (self.upper, self.s_upper), False: (self.lower, self.s_lower)}
        dphi = {}
        for is_up in (True, False):
            own, s_own = chains[is_up]
            other, s_other = chains[not is_up]
            q = cyl[own[1:-1]]
            s = s_own[1:-1]
            opp = np.column_stack([np.interp(s, s_other, cyl[other, j]) for j in range(3)])
            q_up, q_lo = (q, opp) if is_up else (opp, q)
            g = q_up[:, 2] - q_lo[:, 2]
            share = np.where(g >= 0, LOWER_SHARE, 0.5)  # crossed margins meet half way
            q_m = q_lo + share[:, None] * (q_up - q_lo)
            # closure: the palpebral contraction, or margins that touch or have crossed
            touch = np.clip(1.0 - g / TOUCH_RAD, 0.0, 1.0)
            kk = np.maximum(k, touch * touch * (3.0 - 2.0 * touch))
            target = q_m + (1.0 - kk)[:, None] * (q - q_m)
            if is_up and lev > 0:
                target[:, 2] += (1.0 - kk) * lev * self.raise_rad * self.raise_shape[1:-1]
            out[own[1:-1]] = _cartesian(target, c)
            dphi[is_up] = np.r_[0.0, target[:, 2] - q[:, 2], 0.0]
        # the skin around follows its margin's rotation at its x
        for is_up in (True, False):
            ring, s_ring, w = self.rings[is_up]
            q = cyl[ring]
            q[:, 2] += w * np.interp(s_ring, chains[is_up][1], dphi[is_up])
            out[ring] = _cartesian(q, c)
        # contact: no lid vertex inside the eyeball
        v = self.vertices
        r = out[v] - c
        dist = np.linalg.norm(r, axis=1)
        lim = EYE_RADIUS_MM + CONTACT_MM
        bad = dist < lim
        if bad.any():
            out[v[bad]] = c + r[bad] * (lim / np.maximum(dist[bad], 1e-12))[:, None]


class Eyelids:
    """The eyelids of a face model: the lid geometry of each eye with a lid muscle.

    Built once from the rest face and the muscle set (:func:`build_eyelids`); immutable.

    Attributes
    ----------
    eyes : dict of landmark group -> eye geometry (``center`` (3,) mm, the eyeball's centre;
        ``upper`` / ``lower`` the margin chains, canthi at their ends; ``vertices`` every
        vertex the lids may move).
    """

    def __init__(self, eyes: dict):
        self.eyes = dict(eyes)

    @property
    def vertices(self) -> np.ndarray:
        """Every skin vertex the lids may move (sorted)."""
        return np.unique(np.concatenate([e.vertices for e in self.eyes.values()]))

    def apply(self, skin: np.ndarray, contractions: np.ndarray) -> np.ndarray:
        """The skin (V, 3) mm with the lids placed for ``contractions`` (M,) (a new array).

        ``skin`` is the tissue's skin (:attr:`FaceState.x` of the skin nodes)."""
        out = np.array(skin, dtype=np.float64)
        for eye in self.eyes.values():
            eye.apply(skin, contractions, out)
        return out


def build_eyelids(face, muscles) -> Eyelids | None:
    """The eyelids of ``face`` (rest) moved by the lid muscles of ``muscles`` (a MuscleSet);
    None when it has no lid muscle or the face lacks their eye openings."""
    by_eye: dict[str, dict] = {}
    for i, m in enumerate(muscles.muscles):
        if getattr(m, "kind", "") != "lid":
            continue
        slot = by_eye.setdefault(m.eye, {})
        if m.action in slot:
            raise MyofaceValueError(
                f"two lid muscles with action {m.action!r} on {m.eye}: "
                f"{muscles.ids[slot[m.action][0]]} and {m.id}"
            )
        slot[m.action] = (i, m)
    eyes = {}
    for group, slot in by_eye.items():
        loop = eye_loop(face, group)
        if loop is None:
            continue
        raise_i, lev = slot.get("raise", (None, None))
        close_i = slot.get("close", (None, None))[0]
        angle = np.deg2rad(lev.angle_deg) if lev is not None else 0.0
        eyes[group] = _Eye(face.vertices, loop, raise_i, close_i, angle)
    return Eyelids(eyes) if eyes else None
