"""The native core (src/bindings.cpp), in the build this CPU runs best: ``_core_native``
when the package was built for its machine (``-Ccmake.define.VTKRAYCAST_NATIVE=ON``), else
``_core_avx2`` on CPUs with AVX2 and FMA, else ``_core_baseline`` (any x86-64). Every build
gives the same results bit for bit. ``VTKRAYCAST_CORE=baseline|avx2|native`` forces one
(tests do, to compare them)."""

from __future__ import annotations

import os
from importlib import import_module
from types import ModuleType


def _load() -> ModuleType:
    forced = os.environ.get("VTKRAYCAST_CORE")
    if forced:
        if forced not in ("baseline", "avx2", "native"):
            raise ImportError(f"VTKRAYCAST_CORE must be baseline, avx2 or native, got {forced!r}")
        return import_module(f"._core_{forced}", __package__)
    try:
        return import_module("._core_native", __package__)
    except ImportError:
        pass
    baseline = import_module("._core_baseline", __package__)
    return import_module("._core_avx2", __package__) if baseline.cpu_supports_avx2() else baseline


_module = _load()
globals().update({name: getattr(_module, name) for name in dir(_module) if not name.startswith("__")})
name = _module.__name__.rsplit("_", 1)[-1]  #: which build: "baseline", "avx2" or "native"
