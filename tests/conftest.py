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
