"""The portable builds of the core (CMakeLists.txt, vtkraycast/_core.py): baseline x86-64
and AVX2 give the same arrays bit for bit, each forced in turn, and the package runs on
older CPUs: under qemu-user (Debian's qemu-user, as .ci/run installs it) as a Sandy Bridge
(AVX, no AVX2) it picks the baseline build, as a Haswell the AVX2 one, with the same
results; as a Westmere (no AVX at all), which numpy's wheels no longer run on (2.4 and
later), the core alone (builds/core_probe.py, no numpy) picks the baseline build and gives
the same bytes. So does a wheel `pip wheel .` builds here, unpacked as it would be
installed elsewhere."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from vtkraycast import _core

PROBE = Path(__file__).resolve().parent / "builds" / "probe.py"
CORE_PROBE = Path(__file__).resolve().parent / "builds" / "core_probe.py"
OLDER_CPUS = (("SandyBridge", "baseline"), ("Haswell", "avx2"))  # the whole package, numpy and all
QEMU = shutil.which("qemu-x86_64")


def _probe(
    tmp_path: Path, tag: str, *, core: str | None = None, cpu: str | None = None, site: Path | None = None
) -> dict[str, np.ndarray]:
    out = tmp_path / f"{tag}.npz"
    env = dict(os.environ)
    env.pop("VTKRAYCAST_CORE", None)
    if site:
        env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
    if core:
        env["VTKRAYCAST_CORE"] = core
    command = [sys.executable, str(PROBE), str(out)]
    if cpu:
        command = [QEMU, "-cpu", cpu, *command]
        # (numpy's OpenBLAS picks Sandy Bridge kernels there that qemu's emulation cannot
        # run; pyvista's transforms call it, and BLAS is not what is tested here)
        env["OPENBLAS_CORETYPE"] = "Nehalem"
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, f"{' '.join(command)}:\n{done.stdout}\n{done.stderr}"
    return dict(np.load(out))


def _core_probe(tmp_path: Path, tag: str, package: Path, cpu: str | None = None) -> tuple[str, bytes]:
    """The core build core_probe.py loads from ``package`` and the bytes of its outputs."""
    out = tmp_path / f"{tag}.bin"
    env = {k: v for k, v in os.environ.items() if k != "VTKRAYCAST_CORE"}
    command = [sys.executable, str(CORE_PROBE), str(package), str(out)]
    if cpu:
        command = [QEMU, "-cpu", cpu, *command]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, f"{' '.join(command)}:\n{done.stdout}\n{done.stderr}"
    name, _, outputs = out.read_bytes().partition(b"\n")
    return name.decode(), outputs


def _assert_same(got: dict, expected: dict, what: str) -> None:
    assert set(got) == set(expected), what
    for name in expected:
        if name not in ("core", "module"):
            np.testing.assert_array_equal(got[name], expected[name], err_msg=f"{what}: {name}")


def _builds() -> list[str]:
    here = Path(_core.__file__).parent
    return sorted(p.name.split(".")[0].removeprefix("_core_") for p in here.glob("_core_*.so"))


def test_every_build_gives_the_same_arrays(tmp_path):
    builds = _builds()
    if builds == ["native"]:
        pytest.skip("built with VTKRAYCAST_NATIVE=ON: one core only")
    assert builds == ["avx2", "baseline"]
    default = _probe(tmp_path, "default")
    assert str(default["core"]) == ("avx2" if _core.cpu_supports_avx2() else "baseline")
    for build in ("baseline", "avx2") if _core.cpu_supports_avx2() else ("baseline",):
        forced = _probe(tmp_path, build, core=build)
        assert str(forced["core"]) == build
        _assert_same(forced, default, build)


@pytest.mark.skipif(QEMU is None, reason="qemu-user is not installed (apt-get install qemu-user; .ci/run does)")
@pytest.mark.parametrize(("cpu", "build"), OLDER_CPUS)
def test_runs_on_older_cpus(tmp_path, cpu, build):
    if _builds() == ["native"]:
        pytest.skip("built with VTKRAYCAST_NATIVE=ON: for this machine only")
    emulated = _probe(tmp_path, cpu, cpu=cpu)
    assert str(emulated["core"]) == build
    _assert_same(emulated, _probe(tmp_path, "host"), cpu)


@pytest.mark.skipif(QEMU is None, reason="qemu-user is not installed (apt-get install qemu-user; .ci/run does)")
def test_the_core_runs_on_a_cpu_without_avx(tmp_path):
    if _builds() == ["native"]:
        pytest.skip("built with VTKRAYCAST_NATIVE=ON: for this machine only")
    package = Path(_core.__file__).parent
    name, outputs = _core_probe(tmp_path, "westmere", package, cpu="Westmere")
    assert name == "baseline"
    host_name, host_outputs = _core_probe(tmp_path, "host", package)
    assert host_name == _core.name
    assert outputs == host_outputs  # (every build, bit for bit)


@pytest.mark.skipif(QEMU is None, reason="qemu-user is not installed (apt-get install qemu-user; .ci/run does)")
def test_a_wheel_built_here_runs_on_older_cpus(tmp_path):
    root = Path(__file__).resolve().parents[1]
    if not (root / "pyproject.toml").is_file():
        pytest.skip("not run from a checkout")
    wheelhouse = tmp_path / "wheelhouse"
    command = [sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--wheel-dir", str(wheelhouse), str(root)]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("CMAKE_", "SKBUILD_"))}
    done = subprocess.run(command, capture_output=True, text=True, timeout=1800, check=False, env=env)
    assert done.returncode == 0, f"{' '.join(command)}:\n{done.stdout}\n{done.stderr}"
    (wheel,) = wheelhouse.glob("vtkraycast-*.whl")
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as archive:
        archive.extractall(site)
    assert sorted(p.name.split(".")[0] for p in (site / "vtkraycast").glob("_core_*.so")) == [
        "_core_avx2",
        "_core_baseline",
    ]
    host = _probe(tmp_path, "host")
    for cpu, build in OLDER_CPUS:
        emulated = _probe(tmp_path, f"wheel-{cpu}", cpu=cpu, site=site)
        assert str(emulated["core"]) == build
        assert Path(str(emulated["module"])).is_relative_to(site)  # the wheel's package, not the installed one
        _assert_same(emulated, host, f"wheel under {cpu}")
    name, outputs = _core_probe(tmp_path, "wheel-Westmere", site / "vtkraycast", cpu="Westmere")
    assert name == "baseline"
    assert outputs == _core_probe(tmp_path, "host-core", Path(_core.__file__).parent)[1]
