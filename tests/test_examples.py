"""Every script in examples/ runs, passes its own checks and writes a picture.

Each example runs in a fresh interpreter (the one running the tests), in a temporary
directory, with ``--out`` pointing there; new examples are picked up by the glob.
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
EXAMPLES = sorted(
    p
    for p in (ROOT / "examples").glob("*.py")
    if not p.name.startswith("_")  # helper modules, if any, are not examples
)


def test_there_are_examples():
    assert EXAMPLES, "no examples found"


@pytest.mark.parametrize("script", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs_and_writes_a_png(script: pathlib.Path, tmp_path: pathlib.Path):
    env = dict(os.environ, PYVISTA_OFF_SCREEN="true", MPLBACKEND="Agg")
    # The examples must import the installed package (with its compiled core), never the
    # source tree: keep the checkout off their path, as conftest.py does for the tests.
    paths = env.get("PYTHONPATH", "").split(os.pathsep)
    env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p and pathlib.Path(p).resolve() != ROOT)
    result = subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, (
        f"{script.name} exited with {result.returncode}\n"
        f"--- stdout ---\n{result.stdout}\n--- stderr ---\n{result.stderr}"
    )
    pictures = list(tmp_path.glob("*.png"))
    assert pictures, f"{script.name} wrote no PNG into {tmp_path}\n--- stdout ---\n{result.stdout}"
    assert all(p.stat().st_size > 1000 for p in pictures), "a PNG is suspiciously small"
