"""The command line writes a readable geometry buffer and picture."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyvista as pv
from vtkmodules.vtkIOImage import vtkPNGReader


def run(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "vtkraycast", *args]
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=300, check=False)


def read_png(path: Path) -> tuple[int, int]:
    reader = vtkPNGReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput().GetDimensions()[:2]


def test_default_scene_writes_the_buffer_and_the_picture(tmp_path):
    done = run(cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "triangles" in done.stdout and "hits" in done.stdout
    image = pv.read(tmp_path / "raycast.vti")
    assert image.dimensions == (800, 600, 1)
    hits = int(image["vtkValidPointMask"].sum())
    assert 0.02 * image.n_points < hits < image.n_points  # the frog is in view, not filling it
    assert f"{hits} hits" in done.stdout
    assert image["TriangleId"].max() < 1_600_000
    hit = image["vtkValidPointMask"] == 1
    np.testing.assert_allclose(image["Barycentric"][hit].sum(axis=1), 1.0, atol=1e-12)
    assert read_png(tmp_path / "raycast.png") == (800, 600)


def test_a_mesh_file_with_options(tmp_path):
    source = Path(pv.examples.__file__).parent / "nut.ply"
    done = run(str(source), "-o", "nut.vti", "--png", "nut.png", "--size", "64x32", "--view", "+z", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    image = pv.read(tmp_path / "nut.vti")
    assert image.dimensions == (64, 32, 1)
    assert read_png(tmp_path / "nut.png") == (64, 32)


def test_bad_arguments_exit_with_a_message(tmp_path):
    done = run("--size", "0x10", cwd=tmp_path)
    assert done.returncode == 2 and "size must be at least 1x1" in done.stderr
    done = run(str(tmp_path / "missing.vtk"), cwd=tmp_path)
    assert done.returncode == 2 and "cannot read" in done.stderr


def test_a_terminal_sees_a_progress_bar(tmp_path):
    """On a terminal (stderr a tty: here a pseudo-terminal) the cast shows tqdm's bar, which
    ends at 100 %; piped, as in the tests above, nothing but the summary is printed."""
    import fcntl
    import os
    import pty
    import struct
    import termios

    leader, follower = pty.openpty()
    # a terminal 100 columns wide (a fresh pseudo-terminal has none, and tqdm draws nothing)
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    command = [sys.executable, "-m", "vtkraycast", "--size", "1200x900"]
    with subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.PIPE, stderr=follower, text=True) as process:
        os.close(follower)
        seen = b""
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            seen += chunk
        out = process.stdout.read()
    os.close(leader)
    assert process.returncode == 0, seen.decode(errors="replace")
    assert "hits" in out
    text = seen.decode(errors="replace")
    assert "Ray casting" in text and "100%" in text
