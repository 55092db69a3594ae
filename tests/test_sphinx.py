"""The documentation builds with warnings as errors: the API reference from the numpydoc
docstrings, docs/*.md, and the gallery pages from examples/ (the ``docs`` extra)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_documentation_builds_without_warnings(tmp_path):
    pytest.importorskip("sphinx", reason="the docs extra is not installed")
    done = subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS), str(tmp_path / "html")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )  # fmt: skip (cwd: the installed package, not the checkout's sources, is documented)
    assert done.returncode == 0, done.stdout + done.stderr
    api = (tmp_path / "html" / "api.html").read_text()
    for name in ("Scene.intersect_all", "Camera.from_intrinsics", "Lidar", "RayCastFilter"):
        assert name in api, name
    assert (tmp_path / "html" / "auto_examples" / "lidar_and_panorama.html").exists()
