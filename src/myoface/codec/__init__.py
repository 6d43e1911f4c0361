"""Model-based video coding (issue 32): a face video sent as its head pose, muscle contractions,
jaw, lids and gaze, a few dozen bits a frame, after a header that carries the person's model,
the calibration picture and the camera.

- :mod:`myoface.codec.params`: :class:`~myoface.codec.params.FrameParams`, one frame's
  parameters (what a packet carries);
- :mod:`myoface.codec.picture`: :class:`PictureModel`, the receiver's reconstruction of a
  frame from the header and a frame's parameters;
- :mod:`myoface.codec.stream`: the bitstream (docs/codec-format.md): header, packets, the end
  marker; :mod:`myoface.codec.entropy`: the quantiser, the prediction and the range coder;
- :mod:`myoface.codec.encode` / :mod:`myoface.codec.decode`: a video to a stream and back
  (``myoface encode`` / ``myoface decode``).
"""
