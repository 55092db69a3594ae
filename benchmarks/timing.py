"""The timing every benchmark shares: the median of repeated wall-clock runs."""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo on Linux)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def machine_description() -> str:
    """The machine a table was measured on: the platform, the CPU and its cores (the same
    platform string has named machines whose figures differ by 2x)."""
    return f"{platform.platform()}, {cpu_model()}, {os.cpu_count()} cores"


def median_seconds(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall time of ``repeats`` calls of ``fn`` (a shared machine is noisy)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def alternated_ratio(base: Callable[[], Any], other: Callable[[], Any], pairs: int) -> tuple[float, float, float]:
    """Median and quartiles of ``other``'s time over ``base``'s, timed in alternation: each
    pair sees the same state of a shared machine, which separate medians minutes apart do
    not (a caster's own median moved by 15 % between runs here)."""
    ratios = []
    for _ in range(pairs):
        ratios.append(median_seconds(other, 1) / median_seconds(base, 1))
    q1, median, q3 = np.percentile(ratios, [25, 50, 75])
    return float(median), float(q1), float(q3)
