"""Shared test fixtures. Reference data lives in ../shared/data beside the repo (never copied in)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


def shared_path(*parts: str) -> Path:
    """Path of a file in ../shared/data, or skip the test with the reason when it is absent."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(
            f"reference data not available: {p} (../shared/data is only in the dev checkout)"
        )
    return p


def _mediapipe_available() -> bool:
    from myoface.facemesh import mediapipe_available

    return mediapipe_available()


needs_mediapipe = pytest.mark.skipif(
    not _mediapipe_available(), reason='needs pip install "myoface[mediapipe]"'
)


@pytest.fixture(scope="session")
def quick_run(tmp_path_factory):
    """Every benchmark in quick mode, once for the session (``myoface bench --quick --json``):
    the records and their detail. Each benchmark's models and JIT compilation cost most of a
    quick run; the tests that check a benchmark's output read this one run rather than start
    their own; they are all in tests/test_cli_bench.py, so that the suite's workers
    (pytest-xdist, one file to a worker) run it once."""
    import json

    from myoface.cli import main

    out = tmp_path_factory.mktemp("bench") / "all.json"
    assert main(["bench", "--quick", "--json", str(out)]) == 0
    records = json.loads(out.read_text())
    return records, json.loads(out.with_suffix(".detail.json").read_text())


@pytest.fixture(scope="session")
def default_face():
    from myoface.face import load_default_face

    return load_default_face()


@pytest.fixture(scope="session")
def default_tissue(default_face):
    from myoface.tissue import assemble_tissue

    return assemble_tissue(default_face.vertices, default_face.triangles)


def pytest_addoption(parser):
    parser.addoption(
        "--regen-golden",
        action="store_true",
        help="rewrite the golden images under tests/**/golden/ instead of comparing against them",
    )


@pytest.fixture(scope="session")
def regen_golden(request) -> bool:
    """True when the run was started with ``--regen-golden``."""
    return bool(request.config.getoption("--regen-golden"))
