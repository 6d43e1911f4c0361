"""The viewer's export menu: the loaded playback (or the face as it is) as the same glTF file
``myoface export`` writes."""

from __future__ import annotations

import numpy as np
import pytest

from tests.export.conftest import DEMO_CSV


def test_the_viewer_exports_its_playback_and_its_face_as_gltf(export_model, csv_export, tmp_path):
    pytest.importorskip("viser")
    from myoface.export import read_glb_skin
    from myoface.viewer.app import FaceViewer

    viewer = FaceViewer(export_model, port=0)
    try:
        # no playback: the face as the sliders set it, one frame
        viewer.state.set_muscle("zygomaticus_major_l", 0.8)
        still = read_glb_skin(viewer.gltf_export(tmp_path / "face.glb"))
        assert len(still.times) == 1 and "zygomaticus_major_l" in still.names
        corner = int(export_model.face.landmark("mouth_corner_l")[0])
        rest = export_model.skin_vertices()
        assert (still.skin[0, corner] * 1e3 - rest[corner])[1] > 1.0  # the corner rose
        # the demo's CSV loaded for playback: the file myoface export writes from it
        viewer.state.load_playback(DEMO_CSV)
        played = read_glb_skin(viewer.gltf_export(tmp_path / "playback.glb"))
        ref = read_glb_skin(csv_export[0].path)
        assert len(played.times) == len(ref.times) == csv_export[1].n_frames
        np.testing.assert_allclose(played.skin, ref.skin, atol=1e-7)
    finally:
        viewer.close()
