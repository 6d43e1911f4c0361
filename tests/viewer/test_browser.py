"""The viewer in a real headless Chromium: move a muscle slider in the page, the face moves."""

import shutil
import time

import numpy as np
import pytest

from tests.conftest import REPO

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
TALK = REPO / "examples" / "talk.toml"


@pytest.mark.slow
def test_slider_moves_the_face_in_the_browser(tmp_path):
    pytest.importorskip("viser")
    sync_api = pytest.importorskip("playwright.sync_api")
    if CHROMIUM is None:
        pytest.skip("Debian's chromium is not installed (.ci/run installs it)")
    from myoface.model import build_face_model
    from myoface.viewer.app import FaceViewer

    fm = build_face_model()
    corner = int(fm.face.landmark("mouth_corner_l")[0])
    y0 = fm.skin_vertices()[corner, 1]
    viewer = FaceViewer(fm, port=0)

    def live_y():
        return fm.skin_vertices(viewer.worker.current)[corner, 1]

    try:
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(
                executable_path=CHROMIUM,
                headless=True,
                args=[
                    "--no-sandbox",
                    "--disable-gpu",
                    "--disable-background-networking",
                    "--enable-unsafe-swiftshader",
                ],
            )
            page = browser.new_page(viewport={"width": 1000, "height": 700})
            page.goto(viewer.url)
            page.wait_for_selector("canvas", timeout=30000)
            slider = page.get_by_role("slider").first
            slider.wait_for(timeout=30000)
            time.sleep(3.0)  # let the scene arrive and draw
            before = page.screenshot(path=str(tmp_path / "before.png"))
            slider.focus()
            page.keyboard.press("End")  # the first slider: zygomaticus major, left -> 1.0
            deadline = time.time() + 20
            while time.time() < deadline and live_y() - y0 < 2.0:
                time.sleep(0.2)
            time.sleep(2.0)
            after = page.screenshot(path=str(tmp_path / "after.png"))
            rose = live_y() - y0
            # a camera preset moves the browser's camera to the face's left side
            client = next(iter(viewer.server.get_clients().values()))
            page.get_by_text("view", exact=True).click()
            page.get_by_text("camera: profile left").click()
            deadline = time.time() + 20
            while time.time() < deadline and client.camera.position[0] < 0.2:
                time.sleep(0.2)
            cam_x = client.camera.position[0]
            # the page's own screenshot comes back as a PNG download
            page.get_by_text("export", exact=True).click()
            with page.expect_download(timeout=60000) as dl:
                page.get_by_text("screenshot of this view (PNG)").click()
            dl.value.save_as(tmp_path / "shot.png")
            # a playback typed into the page; the browser goes away while it plays
            page.get_by_text("playback", exact=True).click()
            field = page.get_by_text("file (contractions.csv or timeline)", exact=True)
            field.locator("xpath=following::input[1]").fill(str(TALK))
            page.get_by_role("button", name="load", exact=True).click()
            deadline = time.time() + 20
            while time.time() < deadline and viewer.state.playback is None:
                time.sleep(0.2)
            page.get_by_role("button", name="play", exact=True).click()
            # (played: the loop ran or runs; its time slider stays where it ended, so a
            # starved test process that polls after a short playback still sees it)
            deadline = time.time() + 40
            while time.time() < deadline and not (viewer._playing or viewer._time.value > 0):
                time.sleep(0.1)
            played = viewer._playing or viewer._time.value > 0
            browser.close()
        deadline = time.time() + 60  # the playback runs to its end without the browser
        while time.time() < deadline and viewer._playing:
            time.sleep(0.2)
        assert not viewer._playing
        alive = viewer.worker.is_alive()
        after_gone = viewer.apply(fm.validate({"jaw": 0.5}))
    finally:
        viewer.close()
    assert viewer.last_error == ""
    assert played, "the play button did not start the playback"
    assert alive
    assert after_gone[corner, 1] < y0  # the jaw still opens: the server kept working
    assert cam_x > 0.2  # metres along +x: the subject's left
    assert rose > 2.0  # the server's mesh: the corner rose
    import imageio.v3 as iio

    a = iio.imread(before).astype(int)
    b = iio.imread(after).astype(int)
    changed = np.abs(a - b).sum(axis=2) > 30
    # the GUI panel changes too; require changes in the 3-D view (left part of the page)
    assert changed[:, : a.shape[1] // 2].sum() > 50
    shot = iio.imread(tmp_path / "shot.png")
    assert shot.ndim == 3 and shot.shape[0] == 720
    face = np.abs(shot.astype(int) - 255).sum(axis=2) > 60  # not the white page
    assert 0.02 < face.mean() < 0.6
