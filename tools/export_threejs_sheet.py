"""docs/export_threejs.png (``python tools/export_threejs_sheet.py docs/export_threejs.png``):
``myoface export`` of the demo's contractions.csv (tests/export/data) opened by three.js's
GLTFLoader in headless Chromium (the page of tests/export/js, its npm packages installed with
``npm ci``), at rest and at the clip's most moved frame: on the default face, and on the
person's own face made from the sample video's first frame (``myoface face from-photo``)."""

import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.export.conftest import DEMO_CSV  # noqa: E402
from tests.export.test_clients import threejs_page  # noqa: E402
from tools._sheet import grid, labelled  # noqa: E402

from myoface.analysis.sample import fetch_sample_video  # noqa: E402
from myoface.cli import main  # noqa: E402
from myoface.export import clip_from_csv, export_glb  # noqa: E402
from myoface.face.image import read_image  # noqa: E402
from myoface.model import build_face_model, load_face_model  # noqa: E402

out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/export_threejs.png")
tmp = Path(tempfile.mkdtemp())
models = {"default face": build_face_model()}
person = tmp / "person.myoface"
video = str(fetch_sample_video(quiet=True))
if main(["face", "from-photo", video, "-o", str(person)]) == 0:
    models["the person's face"] = load_face_model(person)
tiles = []
for k, (name, model) in enumerate(models.items()):
    clip = clip_from_csv(DEMO_CSV, model)
    rep = export_glb(model, clip, tmp / f"{k}.glb")
    moved = np.sqrt(((rep.sim.skin - rep.sim.skin[0]) ** 2).sum(axis=2)).max(axis=1)
    apex = int(np.argmax(moved))
    folder = tmp / f"page{k}"
    folder.mkdir()
    with threejs_page(rep.path, folder) as page:
        for f in (0, apex):
            page.evaluate(f"window.myoface.seek({f / clip.fps})")
            shot = folder / f"{f}.png"
            page.screenshot(path=str(shot))
            img = read_image(shot, "screenshot")[80:560, 80:560]
            tiles.append(labelled(img, f"three.js, {name}: frame {f} ({f / clip.fps:.2f} s)"))
    print(f"{name}: {rep.summary()}")
Image.fromarray(grid(tiles, 2)).save(out)
print(f"wrote {out}")
