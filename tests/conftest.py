"""Tests run against the installed package (with its compiled core), never the source tree:
`python -m pytest` would otherwise put the checkout first on sys.path."""

from __future__ import annotations

import os
import sys

_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path[:] = [p for p in sys.path if os.path.abspath(p or os.curdir) != _root]
if "vtkraycast" in sys.modules and not hasattr(sys.modules["vtkraycast"], "Scene"):
    del sys.modules["vtkraycast"]

os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")


import subprocess  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture
def run_python(tmp_path):
    """Runs Python code in a fresh interpreter (outside the checkout) and returns it done;
    fails the test with the child's stderr if it did not exit cleanly."""

    def run(code: str, timeout: float = 120) -> subprocess.CompletedProcess:
        command = [sys.executable, "-c", code]
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=tmp_path, check=False)
        assert done.returncode == 0, done.stderr
        return done

    return run
