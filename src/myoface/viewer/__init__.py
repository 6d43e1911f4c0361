"""The interactive web viewer (optional extra: ``pip install "myoface[viewer]"``).

:class:`~myoface.viewer.state.ViewerState` holds the control logic (no GUI needed);
:class:`~myoface.viewer.app.FaceViewer` serves it with viser.
"""

from myoface.viewer.state import PhysicsWorker, ViewerState

__all__ = ["PhysicsWorker", "ViewerState"]
