"""Analysis level: image potentials, snakes and tracking, video input, contraction estimation.

Image coordinates in this package are (x, y) = (column, row) in pixels.
"""

from myoface.analysis.potentials import image_potential, to_intensity
from myoface.analysis.snakes import (
    Contours,
    SnakeParams,
    SnakeResult,
    Snakes,
    SnakeSystem,
    TrackFrame,
    make_contours,
    relax_contours,
    resample_polyline,
    track_contours,
)
from myoface.analysis.video import Video, open_video

__all__ = [
    "Contours",
    "SnakeParams",
    "SnakeResult",
    "SnakeSystem",
    "Snakes",
    "TrackFrame",
    "Video",
    "image_potential",
    "make_contours",
    "open_video",
    "relax_contours",
    "resample_polyline",
    "to_intensity",
    "track_contours",
]
