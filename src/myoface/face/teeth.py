"""The teeth behind the lips: a dental arch fitted to a face's lip landmarks, and the lips' contact
with the teeth and with each other.

A face with the lip landmark groups (``lip_upper_outer``, ``lip_upper_inner``,
``lip_lower_inner``, ``lip_lower_outer``: the default face and the personal faces made from it)
gets a :class:`Dentition`: two arches (upper, fixed to the skull; lower, carried by the jaw),
each a parabolic band in the head frame's horizontal (x, z) plane

    z = z0 - b (x - xc)^2          (the teeth's labial, i.e. front, surface)

with the teeth between it and ``thickness_mm`` behind it, from the incisal edge up (upper) or
down (lower) over the crowns and the gums. The arch is placed from the lips at rest: its front
``LABIAL_GAP_MM`` behind the lips' meeting line at the midline and ``CORNER_GAP_MM`` behind the
mouth corners, the upper incisal edge ``REST_DISPLAY_MM`` below the upper lip's inner margin
(the upper incisors' display of a relaxed face when its lips part; lips that meet at rest, as
the default face's do, cover it with the lower lip) and the lower one ``EDGE_HIDDEN_MM`` below
the lower lip's margin, but at least ``INCISAL_REST_GAP_MM`` below the upper edge (the jaw at
rest holds the teeth apart: with lips that meet, the lower lip's margin is above the upper
incisal edge). Hidden at rest; parted lips, a smile or speech show them.

The contact (:func:`lip_contact`) is a projection of the relaxed skin: lip vertices inside a
tooth band are moved out through its front, and where the upper lip's margin would pass below
the lower lip's both meet halfway (the lips press). The tissue is not changed, only the skin
that is shown and measured. Head frame: x lateral (the subject's left is +x), y up, z forward;
millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: lip landmark groups a face needs for teeth
LIP_GROUPS = ("lip_upper_outer", "lip_upper_inner", "lip_lower_inner", "lip_lower_outer")
#: the teeth's front surface lies this far behind the lips' meeting line at the midline (mm):
#: the thickness of the lips' red margin over the incisors
LABIAL_GAP_MM = 2.5
#: ... and this far behind the mouth corners (mm), so the relaxed corners clear the canines
CORNER_GAP_MM = 4.5
#: the upper incisors show this much below the upper lip at rest, lips apart (mm): 1.91 mm in
#: men, 3.40 mm in women, decreasing with age (R. G. Vig, G. C. Brundo, "The kinetics of
#: anterior tooth display", J. Prosthet. Dent. 39(5):502-504, 1978)
REST_DISPLAY_MM = 2.0
#: the lower incisal edge lies this far inside the lower lip's inner margin at rest (mm): the
#: lower incisors hidden behind the lower lip (their display at rest is about 0.5-1.2 mm, same
#: source: left at zero)
EDGE_HIDDEN_MM = 0.2
#: at rest the lower incisal edge lies at least this far below the upper one (mm): the mandible
#: at rest holds the teeth apart by the freeway space, 2-4 mm in most adults (about 3 mm: M. E.
#: Niswonger, "The rest position of the mandible and the centric relation", J. Am. Dent. Assoc.
#: 21:1572-1582, 1934), less the incisors' vertical overlap when they close (the overbite, about
#: 2 mm in a normal bite): the edges about 1 mm apart, the lower behind the upper (overjet)
INCISAL_REST_GAP_MM = 1.0
#: the lower arch lies this far behind the upper (overjet, mm)
OVERJET_MM = 2.0
#: labio-lingual depth of the tooth band (mm): incisors are about 7 mm thick
THICKNESS_MM = 7.0
#: a lip vertex pushed out of a tooth band ends this far in front of it (mm)
CONTACT_MARGIN_MM = 0.3
#: the skin below the lower lip (between it and the chin, over the lower arch's crowns and
#: gums) is kept at least this far in front of the arch (mm), or as far as it is at rest when
#: that is less: it covers the lower teeth with soft tissue several mm thick, but the face
#: mesh is coarse there (a dozen vertices) and its flat triangles pass inside the curved arch
#: when the vertices are only just out of it. On the sample video's analysed smile the
#: triangles then passed behind the lower teeth and gums as drawn (render.mouth) by up to
#: 1.86 mm on 17 of 24 frames (a glTF client, which draws the teeth where they are, showed
#: them; myoface's renderer draws the mouth's inside only within the lips' opening). 1.5 mm
#: (with the gums 0.45 mm proud of the crowns) covers them on every frame; 2 mm pushed the
#: skin beside the chin's judged points far enough that DIS read the chin on a render of known
#: contractions at a correlation of 0.89 against 0.93 (tests/analysis/test_fidelity.py)
CHIN_CLEARANCE_MM = 1.5
#: a lower-lip vertex within the lower arch's width, from this far above its incisal edge (mm)
#: down over its band, is held in front of the arch whatever its depth
#: (:meth:`Arch.hold_in_front`): a lip cannot pass through the teeth, so one drawn down and
#: back (the depressor labii inferioris with the jaw open) lies on their front. The band's own
#: test (:meth:`Arch.inside`) reaches only ``thickness_mm`` behind the front and not above the
#: edge: on the sample video's analysed smile with the depressor as a sheet (d585611) the lower
#: lip's inner margin beside the midline lay 0.5 mm above the lower incisal edge and 3.4 mm
#: behind its front, its centre 7.5 mm behind (out of the band), and the lip's triangles passed
#: in front of the teeth by 1.0-6.4 mm (tests/render/test_mouth.py); 2 mm covers the mesh's
#: triangles there, as :data:`CHIN_ABOVE_EDGE_MM` below the lip
LIP_ABOVE_EDGE_MM = 2.0
#: ... and ends this far in front of it (mm): the lip's flat triangles between vertices held on
#: the curved front pass behind it by the arc's sagitta, 0.4-0.6 mm over the 7-8 mm between
#: the lower lip's vertices beside the midline (with the 0.3 mm of :data:`CONTACT_MARGIN_MM` the
#: teeth showed through them by 0.15-0.2 mm on the sample's smile)
LIP_HOLD_MARGIN_MM = 1.0
#: projection rounds (teeth and lips alternate; the lower arch's push has a vertical part)
CONTACT_ROUNDS = 4


@dataclass(frozen=True)
class Arch:
    """One dental arch (rest pose, head frame, mm): front surface z = z0 - b (x - xc)^2 for
    |x - xc| <= half_width; the crowns from ``edge_y`` (incisal edge at the midline, rising by
    ``curve`` (x - xc)^2 to the sides: the smile line) over ``height_mm`` towards the gums
    (``direction`` +1 for the upper arch, -1 for the lower)."""

    xc: float
    z0: float
    b: float
    half_width: float
    edge_y: float
    curve: float
    height_mm: float
    direction: float
    thickness_mm: float = THICKNESS_MM

    def front_z(self, x):
        return self.z0 - self.b * (np.asarray(x) - self.xc) ** 2

    def edge(self, x):
        return self.edge_y + self.direction * self.curve * (np.asarray(x) - self.xc) ** 2

    def signed_depth(self, p: np.ndarray) -> np.ndarray:
        """Distance (N,) mm of points (N, 3) in front of the front surface (negative behind),
        along the surface's horizontal normal (first order)."""
        dx = p[:, 0] - self.xc
        return (p[:, 2] - self.front_z(p[:, 0])) / np.sqrt(1.0 + (2.0 * self.b * dx) ** 2)

    def normal(self, p: np.ndarray) -> np.ndarray:
        """Unit outward (forward) normals (N, 3) of the front surface below points (N, 3)."""
        n = np.zeros((len(p), 3))
        n[:, 0] = 2.0 * self.b * (p[:, 0] - self.xc)
        n[:, 2] = 1.0
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def inside(self, p: np.ndarray) -> np.ndarray:
        """Which points (N, 3) lie in the band (crowns and gums)."""
        d = self.signed_depth(p)
        h = self.direction * (p[:, 1] - self.edge(p[:, 0]))
        return (
            (np.abs(p[:, 0] - self.xc) <= self.half_width)
            & (d < 0.0)
            & (d > -self.thickness_mm)
            & (h > 0.0)
            & (h < self.height_mm)
        )

    def push_out(self, p: np.ndarray, margin: float = CONTACT_MARGIN_MM) -> np.ndarray:
        """Points (N, 3) with those inside the band moved forward out of it (copy)."""
        out = np.array(p, dtype=np.float64)
        m = self.inside(out)
        if m.any():
            q = out[m]
            out[m] = q + (margin - self.signed_depth(q))[:, None] * self.normal(q)
        return out

    def hold_in_front(
        self, p: np.ndarray, above_mm: float, margin: float = CONTACT_MARGIN_MM
    ) -> np.ndarray:
        """Points (N, 3) within the arch's width, from ``above_mm`` beyond its edge (above the
        lower one's) over its band's height, and less than ``margin`` in front of its front (or
        behind it at any depth), moved forward to ``margin`` in front of it (copy)."""
        out = np.array(p, dtype=np.float64)
        d = self.signed_depth(out)
        h = self.direction * (out[:, 1] - self.edge(out[:, 0]))
        m = (
            (np.abs(out[:, 0] - self.xc) <= self.half_width)
            & (d < margin)
            & (h > -above_mm)
            & (h < self.height_mm)
        )
        if m.any():
            q = out[m]
            out[m] = q + (margin - d[m])[:, None] * self.normal(q)
        return out


@dataclass(frozen=True)
class Dentition:
    """Upper and lower arches fitted to a face's lips (:func:`fit_dentition`), and the lips'
    vertex sets for the contact: ``upper_lip``/``lower_lip`` (every vertex of each lip),
    ``upper_margin``/``lower_margin`` (the inner margins, paired index by index, corners
    left out)."""

    upper: Arch
    lower: Arch
    upper_lip: np.ndarray
    lower_lip: np.ndarray
    upper_margin: np.ndarray
    lower_margin: np.ndarray
    #: mesiodistal scale of the teeth (1: an average adult mouth, 50 mm corner to corner)
    scale: float = 1.0
    #: the skin below the lower lip over the lower arch (vertex indices) and the least depth
    #: (mm) each keeps in front of it (:data:`CHIN_CLEARANCE_MM`, or its depth at rest)
    chin: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    chin_clearance: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _lip_region(v: np.ndarray, outer: np.ndarray, inner: np.ndarray) -> np.ndarray:
    """Vertices inside (or on) the polygon outer + reversed inner in the front (x, y) view."""
    from matplotlib.path import Path as MplPath

    poly = np.vstack([v[outer, :2], v[inner[::-1], :2]])
    inside = MplPath(poly).contains_points(v[:, :2], radius=1e-6)
    inside |= MplPath(poly).contains_points(v[:, :2], radius=-1e-6)
    # only the front of the face (the back of a closed scan could project into the polygon)
    zmin = min(v[outer, 2].min(), v[inner, 2].min()) - 2.0
    sel = np.flatnonzero(inside & (v[:, 2] > zmin))
    return np.union1d(sel, np.r_[outer, inner]).astype(np.int64)


def fit_dentition(face) -> Dentition | None:
    """The teeth of ``face`` (a FaceMesh at rest, head frame, mm) from its lip landmark groups
    (:data:`LIP_GROUPS`), or None when it lacks them."""
    lm = face.landmarks
    if not all(k in lm and len(lm[k]) >= 3 for k in LIP_GROUPS):
        return None
    v = np.asarray(face.vertices, dtype=np.float64)
    uo, ui, li, lo = (np.asarray(lm[k], dtype=np.int64) for k in LIP_GROUPS)
    cr, cl = v[ui[0]], v[ui[-1]]  # inner corners
    xc = float(0.5 * (cr[0] + cl[0]))
    half = float(0.5 * abs(cl[0] - cr[0]))
    mid_u = v[ui[len(ui) // 2]]
    mid_l = v[li[len(li) // 2]]
    z_mid = float(min(mid_u[2], mid_l[2]))
    z_corner = float(0.5 * (cr[2] + cl[2]))
    z0 = z_mid - LABIAL_GAP_MM
    b = max((z0 - (z_corner - CORNER_GAP_MM)) / half**2, 1e-3)
    mouth_w = float(np.linalg.norm(v[uo[-1]] - v[uo[0]]))
    scale = mouth_w / 50.0
    # the arch reaches back to the first molars, about 30 mm behind the incisors (scaled)
    back = 30.0 * scale
    half_w = float(np.sqrt(back / b))
    # the upper incisal edge REST_DISPLAY_MM below the upper lip (behind the lower lip when the
    # lips meet at rest); the lower one behind the lower lip and below the upper edge
    edge_u = float(mid_u[1]) - REST_DISPLAY_MM * scale
    edge_l = min(float(mid_l[1]) - EDGE_HIDDEN_MM, edge_u - INCISAL_REST_GAP_MM * scale)
    upper = Arch(xc, z0, b, half_w, edge_u, 0.012, 22.0 * scale, 1.0)  # crowns ~10.5 mm + gums
    lb = b * 1.08
    lower = Arch(
        xc, z0 - OVERJET_MM, lb, float(np.sqrt(back / lb)), edge_l, 0.006, 20.0 * scale, -1.0,
    )  # fmt: skip
    inner_u, inner_l = ui[1:-1], li[1:-1]
    n = min(len(inner_u), len(inner_l))
    upper_lip, lower_lip = _lip_region(v, uo, ui), _lip_region(v, lo, li)
    chin, clearance = _chin_region(v, lower, np.union1d(upper_lip, lower_lip))
    return Dentition(
        upper, lower, upper_lip, lower_lip, inner_u[:n], inner_l[:n], scale, chin, clearance
    )


#: the skin over the lower arch that keeps its clearance (:func:`_chin_region`): vertices at
#: rest no more than this far in front of the arch (mm), ...
CHIN_REACH_MM = 15.0
#: ... and from this far above its incisal edge (mm) down over its crowns and gums, to this
#: far below the band (mm): the triangles from a vertex inside the band's height to one below
#: it pass over the gums' lowest part (on the face made from the sample video's photo, by up to
#: 0.6 mm with the vertices below the band left free)
CHIN_ABOVE_EDGE_MM = 2.0
CHIN_BELOW_BAND_MM = 6.0


def _chin_region(v: np.ndarray, lower: Arch, lips: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rest skin's vertices (not of the lips) over the lower arch's band, within
    :data:`CHIN_REACH_MM` in front of it, and the depth each keeps
    (:data:`CHIN_CLEARANCE_MM`, or its depth at rest when that is less)."""
    depth = lower.signed_depth(v)
    near = _over_chin_band(lower, v) & (depth > 0.0) & (depth < CHIN_REACH_MM)
    near[lips] = False
    chin = np.flatnonzero(near).astype(np.int64)
    return chin, np.minimum(CHIN_CLEARANCE_MM, depth[chin])


def _rigid_apply(pose, p):
    rot, shift = pose
    return p @ rot.T + shift


def _rigid_inverse(pose, p):
    rot, shift = pose
    return (p - shift) @ rot


def _press_lips(skin: np.ndarray, d: Dentition) -> None:
    """In place: the upper lip's margin meets the lower's halfway where it passed below it;
    then no upper-lip vertex below the lower margin and no lower-lip vertex above the upper
    margin (at the same x, by linear interpolation along the margins)."""
    yu = skin[d.upper_margin, 1]
    yl = skin[d.lower_margin, 1]
    cross = yu < yl
    if cross.any():
        mid = 0.5 * (yu[cross] + yl[cross])
        skin[d.upper_margin[cross], 1] = mid
        skin[d.lower_margin[cross], 1] = mid
    for lip, margin, sign in (
        (d.upper_lip, d.lower_margin, 1.0),
        (d.lower_lip, d.upper_margin, -1.0),
    ):
        mx, my = skin[margin, 0], skin[margin, 1]
        o = np.argsort(mx)
        mx, my = mx[o], my[o]
        x = skin[lip, 0]
        within = (x >= mx[0]) & (x <= mx[-1])
        bound = np.interp(x, mx, my)
        bad = within & (sign * (skin[lip, 1] - bound) < 0.0)
        # margin vertices of the same lip are handled by the pairing above
        if bad.any():
            skin[lip[bad], 1] = bound[bad]


def lip_contact(skin: np.ndarray, dentition: Dentition, jaw_pose=None) -> np.ndarray:
    """The skin (V, 3) mm with the lips out of the teeth and not through each other (a copy).

    Parameters
    ----------
    skin : (V, 3) float ndarray — relaxed skin vertices, head frame, mm.
    dentition : Dentition — from :func:`fit_dentition` on the rest face.
    jaw_pose : (rotation (3, 3), translation (3,) mm), optional — the lower arch's rigid motion
        from rest (the jaw's rotation, :meth:`myoface.model.FaceModel.jaw_pose`); None: rest.

    Returns
    -------
    (V, 3) float ndarray
        Lip vertices in the upper band pushed out of its front, those in the lower band (tested
        in the jaw's rest frame) out of its front, and the lower lip's behind the lower band's
        front at any depth (:data:`LIP_ABOVE_EDGE_MM`) in front of it; upper-lip margin not
        below the lower's; the skin below the lower lip (:attr:`Dentition.chin`) at least its
        clearance in front of the lower band.
    """
    out = np.array(skin, dtype=np.float64)
    d = dentition
    lips = np.union1d(d.upper_lip, d.lower_lip)
    for _ in range(CONTACT_ROUNDS):
        _press_lips(out, d)
        p = d.upper.push_out(out[lips])
        if jaw_pose is None:
            p = d.lower.push_out(p)
        else:
            p = _rigid_apply(jaw_pose, d.lower.push_out(_rigid_inverse(jaw_pose, p)))
        moved = np.abs(p - out[lips]).max() if len(lips) else 0.0
        out[lips] = p
        # the lower lip on the lower teeth's front, however deep it was drawn
        q = out[d.lower_lip]
        local = q if jaw_pose is None else _rigid_inverse(jaw_pose, q)
        held = d.lower.hold_in_front(local, LIP_ABOVE_EDGE_MM, LIP_HOLD_MARGIN_MM)
        m = np.any(held != local, axis=1)
        if m.any():
            out[d.lower_lip[m]] = held[m] if jaw_pose is None else _rigid_apply(jaw_pose, held[m])
            moved = max(moved, float(np.abs(out[d.lower_lip[m]] - q[m]).max()))
        if moved == 0.0:
            break
    if len(d.chin):
        # the skin below the lower lip clear of the lower arch (in the jaw's rest frame)
        if jaw_pose is None:
            out[d.chin] = _keep_clear(d.lower, out[d.chin], d.chin_clearance)
        else:
            q = _keep_clear(d.lower, _rigid_inverse(jaw_pose, out[d.chin]), d.chin_clearance)
            out[d.chin] = _rigid_apply(jaw_pose, q)
    return out


def _over_chin_band(arch: Arch, p: np.ndarray) -> np.ndarray:
    """Which points (N, 3) lie within the arch's width and from :data:`CHIN_ABOVE_EDGE_MM`
    above its edge down to :data:`CHIN_BELOW_BAND_MM` below its band (at any depth)."""
    h = arch.direction * (p[:, 1] - arch.edge(p[:, 0]))
    return (
        (np.abs(p[:, 0] - arch.xc) <= arch.half_width)
        & (h > -CHIN_ABOVE_EDGE_MM)
        & (h < arch.height_mm + CHIN_BELOW_BAND_MM)
    )


def _keep_clear(arch: Arch, p: np.ndarray, clearance: np.ndarray) -> np.ndarray:
    """Points (N, 3) over the arch's band (within its width and height, and down to
    :data:`CHIN_BELOW_BAND_MM` below it) and less than
    ``clearance`` (N,) mm in front of it (or inside it) moved forward to ``clearance``."""
    out = np.array(p, dtype=np.float64)
    depth = arch.signed_depth(out)
    over = _over_chin_band(arch, out) & (depth > -arch.thickness_mm) & (depth < clearance)
    if over.any():
        q = out[over]
        out[over] = q + (clearance[over] - depth[over])[:, None] * arch.normal(q)
    return out


def contact_violations(skin: np.ndarray, dentition: Dentition, jaw_pose=None) -> dict:
    """How far the skin is from the contact's conditions (for tests and checks): the number of
    lip vertices inside each band and the largest drop (mm) of the upper-lip margin below the
    lower's (0 when none)."""
    d = dentition
    lips = np.union1d(d.upper_lip, d.lower_lip)
    p = np.asarray(skin, dtype=np.float64)[lips]
    low = p if jaw_pose is None else _rigid_inverse(jaw_pose, p)
    drop = np.asarray(skin)[d.lower_margin, 1] - np.asarray(skin)[d.upper_margin, 1]
    return {
        "in_upper": int(d.upper.inside(p).sum()),
        "in_lower": int(d.lower.inside(low).sum()),
        # (a drop within rounding, 1e-9 mm, of the margins met halfway is no cross)
        "lip_cross_mm": float(drop.max()) if len(drop) and drop.max() > 1e-9 else 0.0,
    }
