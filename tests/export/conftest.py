"""Fixtures of the glTF export's tests: the default model, and the exports of the demo's
contractions.csv (``data/single_face_contractions.csv``: ``myoface analyze single_face.mp4
--tracker landmarks``, 72 frames at 30 fps with head pose and gaze; the columns of the
depressor supercilii and the orbicularis oculi's upper part, added to the muscle set after it
was made, at 0) and of each expression, made once per session."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
DEMO_CSV = HERE / "data" / "single_face_contractions.csv"
JS = HERE / "js"
#: under this environment variable (set by .ci/run) a missing client fails its test
REQUIRE_CLIENTS = os.environ.get("MYOFACE_REQUIRE_CLIENTS") == "1"


def need_client(ok: bool, reason: str) -> None:
    """Skip (locally) or fail (CI, MYOFACE_REQUIRE_CLIENTS=1) a test whose client is missing."""
    if ok:
        return
    if REQUIRE_CLIENTS:
        pytest.fail(f"{reason} (MYOFACE_REQUIRE_CLIENTS=1: the clients must be there)")
    pytest.skip(reason)


def node_modules_ok() -> bool:
    return (JS / "node_modules" / "three").is_dir() and (
        JS / "node_modules" / "gltf-validator"
    ).is_dir()


def need_node() -> str:
    node = shutil.which("node")
    need_client(node is not None, "node is not installed (.ci/run installs Debian's nodejs)")
    need_client(node_modules_ok(), f"the npm packages are not installed: (cd {JS} && npm ci)")
    return node


@pytest.fixture(scope="session")
def export_model():
    from myoface.model import build_face_model

    return build_face_model()


@pytest.fixture(scope="session")
def csv_export(export_model, tmp_path_factory):
    """(report, clip) of ``myoface export`` on the demo's CSV."""
    from myoface.export import clip_from_csv, export_glb

    clip = clip_from_csv(DEMO_CSV, export_model)
    out = tmp_path_factory.mktemp("export") / "demo.glb"
    return export_glb(export_model, clip, out), clip


@pytest.fixture(scope="session")
def expression_exports(export_model, tmp_path_factory):
    """{name: (report, clip)} of each expression at full intensity, at 15 fps (a short clip)."""
    from myoface.control import list_expressions
    from myoface.export import clip_from_expressions, export_glb

    folder = tmp_path_factory.mktemp("expressions")
    out = {}
    for name in list_expressions():
        clip = clip_from_expressions([(name, 1.0)], export_model, fps=15.0)
        out[name] = (export_glb(export_model, clip, folder / f"{name}.glb"), clip)
    return out
