#!/usr/bin/env bash
# Builds vtkraycast's native core with AddressSanitizer + UndefinedBehaviorSanitizer into a
# throwaway venv and runs the core-facing tests under them. Exits non-zero on any test failure
# or sanitizer report. Touches neither /work/venv nor the checkout's build/ directory.
#
#   benchmarks/sanitizers.sh [--workdir DIR] [extra pytest args...]
#
# DIR holds venv/ (~1 GB), build/, reports/ and logs; reusing one makes reruns incremental.
# Default: a fresh /tmp/vtkraycast-san.XXXX, removed after a clean run, kept otherwise.
# PYTHON picks the interpreter for the venv (default python3).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK="" TEMP=""
if [[ "${1:-}" == "--workdir" ]]; then WORK=$2; shift 2; fi
if [[ -z "$WORK" ]]; then TEMP=$(mktemp -d /tmp/vtkraycast-san.XXXX); WORK=$TEMP; fi
mkdir -p "$WORK" && WORK=$(cd "$WORK" && pwd)
PY="$WORK/venv/bin/python"
echo "== workdir $WORK"

# 1. Throwaway venv with the runtime + test deps and the build backend (for --no-build-isolation).
[[ -x "$PY" ]] || "${PYTHON:-python3}" -m venv "$WORK/venv"
"$PY" -m pip install -q "numpy>=1.24" "vtk>=9.2" "pyvista>=0.48" "tqdm>=4" \
    "pytest>=7" "libigl>=2.6" "hypothesis>=6" "matplotlib>=3.6" "scikit-build-core>=0.10" "nanobind>=2.4" "open3d"

# 2. Build the core instrumented. The project's -march and -fno-fast-math -ffp-contract=off
#    are added by CMakeLists.txt on top of these. Build type Debug with its flags set to -O1 -g:
#    nanobind_add_module appends -Os in Release/RelWithDebInfo, which would override -O1; Debug
#    gets no -Os and no -DNDEBUG (asserts stay live). nanobind (NB_STATIC) gets the same flags.
SAN="-fsanitize=address,undefined,float-cast-overflow -fno-omit-frame-pointer -fno-sanitize-recover=undefined,float-cast-overflow"
ASAN_LIB=$(gcc -print-file-name=libasan.so)
UBSAN_LIB=$(gcc -print-file-name=libubsan.so)
echo "== building (log: $WORK/build.log)"
# The build imports the fresh module once (nanobind_add_stub) into an uninstrumented python,
# where ASan would refuse to load after libc: verify_asan_link_order=0 lets that one import be.
ASAN_OPTIONS=verify_asan_link_order=0:detect_leaks=0 \
"$PY" -m pip install -v --no-build-isolation --no-deps --force-reinstall \
    -C cmake.build-type=Debug \
    -C "cmake.define.CMAKE_CXX_FLAGS=$SAN" \
    -C "cmake.define.CMAKE_CXX_FLAGS_DEBUG=-O1 -g" \
    -C "cmake.define.CMAKE_SHARED_LINKER_FLAGS=-fsanitize=address,undefined" \
    -C "cmake.define.CMAKE_MODULE_LINKER_FLAGS=-fsanitize=address,undefined" \
    -C "build-dir=$WORK/build" \
    "$ROOT" >"$WORK/build.log" 2>&1 || { tail -40 "$WORK/build.log"; exit 1; }

# 3. Sanitizer runtime for an uninstrumented CPython: preload it (ASan must come first).
#    detect_leaks=0: CPython's own allocations (interned objects, module state kept until exit)
#    are not leak-clean, so LeakSanitizer would only report the interpreter.
#    ASan reports go to files in reports/ (one per process, subprocesses included); abort/halt
#    make any report also fail the test or the run. GCC's UBSan ignores log_path and writes to
#    stderr: pytest runs with --capture=sys so C-level stderr reaches pytest.log uncaptured.
#    PYTHONMALLOC=malloc routes Python objects through ASan's allocator too.
rm -rf "$WORK/reports" && mkdir -p "$WORK/reports"
export LD_PRELOAD="$ASAN_LIB $UBSAN_LIB" PYTHONMALLOC=malloc PYTHONDONTWRITEBYTECODE=1
export HYPOTHESIS_STORAGE_DIRECTORY="$WORK/.hypothesis"  # keep the checkout clean
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:log_path=$WORK/reports/asan"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"

# The instrumented module must be the one imported (not /work/venv's, not the checkout).
cd "$WORK"
CORE=$("$PY" -c "import vtkraycast._core as c; print(c._module.__file__)")
echo "== imported core: $CORE"
[[ "$CORE" == "$WORK/venv/"* ]] || { echo "not the sanitizer build"; exit 1; }
SYMS=$(nm -D "$CORE")
grep -q "__asan_init" <<<"$SYMS" || { echo "core lacks __asan_init"; exit 1; }
grep -q "__ubsan_handle_" <<<"$SYMS" || { echo "core lacks UBSan handlers"; exit 1; }
env -u LD_PRELOAD ldd "$CORE" | grep -E "libasan|libubsan"

# 4. Core-facing tests. Run from $WORK; tests/conftest.py also strips the checkout from sys.path.
#    No exclusions are needed: these tests render through the core, not through VTK's OpenGL.
#    (One red vtkExecutive "returned failure" log line is expected: a filter test aborts on purpose.)
T="$ROOT/tests"
set +e
"$PY" -m pytest -p no:cacheprovider --capture=sys -q "$T/test_scene.py" "$T/test_strategies.py" "$T/test_mesh.py" \
    "$T/test_validate.py" "$T/test_filter.py" "$T/test_reference_libigl.py" "$T/test_tiles.py" "$T/test_rays.py" \
    "$T/test_sensors.py" "$@" 2>&1 | tee "$WORK/pytest.log"
STATUS=${PIPESTATUS[0]}
set -e

# 5. Any non-empty ASan report file, or UBSan "runtime error:" line, is a finding.
REPORTS=$(grep -c ": runtime error: " "$WORK/pytest.log" || true)
for f in "$WORK"/reports/*; do
    [[ -s "$f" ]] || continue
    REPORTS=$((REPORTS + 1)); echo "== sanitizer report $f"; cat "$f"
done
PASSED=$(grep -oE "[0-9]+ passed" "$WORK/pytest.log" | tail -1 | cut -d' ' -f1 || true)
FAILED=$(grep -oE "[0-9]+ (failed|error)" "$WORK/pytest.log" | tail -1 | cut -d' ' -f1 || true)
echo "ASan+UBSan: ${PASSED:-0} passed, ${FAILED:-0} failed (pytest exit $STATUS); sanitizer reports: $REPORTS"
[[ $STATUS -eq 0 && $REPORTS -eq 0 ]] || exit 1
if [[ -n "$TEMP" ]]; then cd / && rm -rf "$TEMP"; fi
