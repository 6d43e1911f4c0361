"""``MuscleSet``: the muscles (and jaw) of one face, their ids and the contraction vector."""

from __future__ import annotations

import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.muscles.jaw import Jaw
from myoface.muscles.types import Muscle

#: the id of the jaw-opening control in every MuscleSet that has a jaw
JAW_ID = "jaw"


@dataclass(frozen=True)
class BoundSkin:
    """Skin bound to the muscle under it: where mimetic muscles insert into the dermis with no
    mobile fat between (the lower lip, the chin), the lattice's fat layer under ``vertices``
    takes the stiffness ``fat`` = (alpha, beta, strain_c) (eq. 2) instead of the fat's own
    (:func:`myoface.tissue.assemble.bind_layer`)."""

    vertices: np.ndarray
    fat: tuple[float, float, float]
    note: str = ""

    def __post_init__(self):
        v = np.unique(np.asarray(self.vertices, dtype=np.int64))
        if v.ndim != 1 or len(v) == 0 or v.min() < 0:
            raise MyofaceValueError("bound skin needs a non-empty list of vertex indices")
        object.__setattr__(self, "vertices", v)
        a, b, c = (float(x) for x in self.fat)
        if not (0 < a <= b and c >= 0):
            raise MyofaceValueError(
                f"bound skin's fat needs 0 < alpha <= beta, strain_c >= 0; got {self.fat}"
            )
        object.__setattr__(self, "fat", (a, b, c))


class MuscleSet:
    """The actuators of a face: muscles with unique ids, plus optionally the jaw.

    Contractions are vectors c (M,) in [0, 1] ordered like :attr:`ids`; the jaw, when present,
    is the last entry (``"jaw"``), mapping [0, 1] to the mandible's opening (rotation
    ``jaw.angle_rad(c)``, up to ``jaw.max_angle_rad``, and condylar slide ``jaw.slide(c)``).

    Parameters
    ----------
    muscles : sequence of LinearMuscle, WatersMuscle, SheetMuscle, SphincterMuscle
    jaw : Jaw, optional
    name : str
    """

    def __init__(
        self,
        muscles: Sequence[Muscle],
        jaw: Jaw | None = None,
        name: str = "",
        bound_skin: BoundSkin | None = None,
    ):
        self.muscles: tuple[Muscle, ...] = tuple(muscles)
        self.jaw = jaw
        self.name = name
        self.bound_skin = bound_skin
        ids = [m.id for m in self.muscles]
        if JAW_ID in ids:
            raise MyofaceValueError(f"muscle id {JAW_ID!r} is reserved for the jaw")
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise MyofaceValueError(f"duplicate muscle ids: {dup}")
        self.ids: tuple[str, ...] = tuple(ids) + ((JAW_ID,) if jaw is not None else ())
        self._index = {k: i for i, k in enumerate(self.ids)}

    def __len__(self) -> int:
        return len(self.ids)

    def __repr__(self) -> str:
        jaw = " + jaw" if self.jaw is not None else ""
        return f"MuscleSet({self.name!r}: {len(self.muscles)} muscles{jaw})"

    def __getitem__(self, muscle_id: str) -> Muscle:
        i = self.index(muscle_id)
        if muscle_id == JAW_ID:
            raise MyofaceValueError("the jaw is not a muscle; use MuscleSet.jaw")
        return self.muscles[i]

    @property
    def jaw_index(self) -> int | None:
        """Position of ``"jaw"`` in :attr:`ids` (None without a jaw)."""
        return self._index.get(JAW_ID)

    @property
    def mandible_index(self) -> tuple[int, ...]:
        """Positions in :attr:`ids` of the muscles that turn the mandible (``acts_on ==
        "bone"``: the lateral pterygoids)."""
        return tuple(i for i, m in enumerate(self.muscles) if getattr(m, "acts_on", "") == "bone")

    @property
    def bone_index(self) -> tuple[int, ...]:
        """Positions in :attr:`ids` of what moves bone, not soft tissue: the muscles that turn
        the mandible (:attr:`mandible_index`) and the jaw."""
        return self.mandible_index + ((self.jaw_index,) if self.jaw_index is not None else ())

    def index(self, muscle_id: str) -> int:
        try:
            return self._index[muscle_id]
        except KeyError:
            raise MyofaceValueError(self._unknown(muscle_id)) from None

    def _unknown(self, muscle_id) -> str:
        close = difflib.get_close_matches(str(muscle_id), self.ids, n=3)
        hint = f"; did you mean {', '.join(close)}?" if close else ""
        return f"unknown muscle id {muscle_id!r} for {self.name or 'this face'}{hint}"

    def mirror_pairs(self) -> list[tuple[str, str]]:
        """(left id, right id) for every muscle whose id ends in ``_l`` and has an ``_r`` twin."""
        return [
            (i, i[:-2] + "_r")
            for i in self.ids
            if i.endswith("_l") and i[:-2] + "_r" in self._index
        ]

    def validate(self, contractions) -> np.ndarray:
        """Check contractions and return them as a float64 vector (M,) in :attr:`ids` order.

        ``contractions`` is a mapping ``{id: value}`` (missing ids are 0) or a sequence/array of
        length M. Values must be finite and in [0, 1].

        Raises
        ------
        MyofaceValueError
            Naming the offending id and value, e.g. ``contractions must be finite and in
            [0, 1]; got 1.7 for zygomaticus_major_l``.
        """
        m = len(self.ids)
        if isinstance(contractions, Mapping):
            c = np.zeros(m)
            for k, v in contractions.items():
                if k not in self._index:
                    raise MyofaceValueError(self._unknown(k))
                try:
                    c[self._index[k]] = float(v)
                except (TypeError, ValueError):
                    raise MyofaceValueError(
                        f"contraction of {k} must be a number; got {v!r}"
                    ) from None
        else:
            try:
                c = np.array(contractions, dtype=np.float64)
            except (TypeError, ValueError):
                raise MyofaceValueError(
                    "contractions must be a mapping {muscle id: value} or a numeric vector"
                ) from None
            if c.shape != (m,):
                raise MyofaceValueError(
                    f"contractions must have shape ({m},) (one per id of {self!r}); got {c.shape}"
                )
        bad = ~np.isfinite(c) | (c < 0) | (c > 1)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise MyofaceValueError(
                f"contractions must be finite and in [0, 1]; got {c[i]:g} for {self.ids[i]}"
            )
        return c

    def as_dict(self, contractions) -> dict[str, float]:
        c = self.validate(contractions)
        return {k: float(v) for k, v in zip(self.ids, c, strict=True)}

    def basis(self, points: np.ndarray, lower: np.ndarray | None = None) -> np.ndarray:
        """Displacement per unit contraction, (N, 3, M) mm, of ``points`` (N, 3) mm.

        ``lower`` (N,) are the points' jaw weights (for the ``region`` of each muscle; default
        0.5 everywhere). The jaw column is zero: the jaw rotates, see :meth:`Jaw.rotate`.

        References: Terzopoulos & Waters 1993, eq. (5).
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
            raise MyofaceValueError(f"points must be a finite (N, 3) array; got {p.shape}")
        lw = np.full(len(p), 0.5) if lower is None else np.asarray(lower, dtype=np.float64)
        if lw.shape != (len(p),):
            raise MyofaceValueError(f"lower must have shape ({len(p)},); got {lw.shape}")
        out = np.zeros((len(p), 3, len(self.ids)))
        for i, mus in enumerate(self.muscles):
            out[:, :, i] = mus.field(p, lw)
        return out
