// Python bindings of the native core (the private module vtkraycast._core). Arrays cross
// without copies; dtypes and layouts are fixed by the Python side. The GIL is released
// during every build and cast and re-taken only to report progress and check signals.
#include <nanobind/nanobind.h>
#include <nanobind/stl/array.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/function.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <type_traits>

#include "all_hits.hpp"
#include "bvh.hpp"
#include "camera_rays.hpp"
#include "inside_grid.hpp"
#include "kernel_cramer.hpp"
#include "kernel_moller_trumbore.hpp"
#include "kernel_plane.hpp"
#include "kernel_watertight.hpp"
#include "ray_extent.hpp"
#include "render.hpp"
#include "take_rows.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using Points = nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Triangles = nb::ndarray<const uint32_t, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using IdsOut = nb::ndarray<int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

/// A numpy array owning `data` (new[]), shape (rows) or (rows, width).
template <class T>
nb::ndarray<nb::numpy, T> owned_array(T* data, std::size_t rows, std::size_t width) {
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
    const std::size_t shape[2] = {rows, width};
    return nb::ndarray<nb::numpy, T>(data, width == 1 ? 1 : 2, shape, owner);
}

unsigned resolve_threads(int threads) {
    if (threads < 0) throw std::invalid_argument("threads must be >= 1 (or None for all cores)");
    // (asked once: glibc reads /sys for it, which took longer than casting a ray)
    static const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
    return threads == 0 ? cores : unsigned(threads);
}

/// Polls from the calling thread: re-takes the GIL, lets Ctrl-C and the Python callback
/// stop the cast. A Python exception is kept and re-raised once the workers have stopped.
struct PythonPoll {
    std::optional<nb::callable> callback;
    bool raised = false;
    bool operator()(std::size_t done, std::size_t total) {
        nb::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {
            raised = true;
            return false;
        }
        if (!callback) return true;
        try {
            return nb::cast<bool>((*callback)(done, total));
        } catch (nb::python_error& e) {
            e.restore();
            raised = true;
            return false;
        }
    }
};

enum class Strategy { Auto, Watertight, Plane, Cramer, MollerTrumbore };

Strategy parse_strategy(const std::string& name) {
    if (name == "auto") return Strategy::Auto;
    if (name == "watertight") return Strategy::Watertight;
    if (name == "plane") return Strategy::Plane;
    if (name == "cramer") return Strategy::Cramer;
    if (name == "moller-trumbore") return Strategy::MollerTrumbore;
    throw std::invalid_argument("unknown strategy '" + name + "'");
}

bool parse_accel(const std::string& name) {
    if (name == "bvh") return false;
    if (name == "none") return true;
    throw std::invalid_argument("unknown accel '" + name + "'");
}

template <template <class> class Kernel, class Real, class Rays>
bool render_with(const vrc::Scene& scene, const Rays& rays, bool brute_force, const vrc::Outputs<Real>& out,
                 const vrc::CastContext& context, unsigned threads, const vrc::Poll& poll) {
    return brute_force ? vrc::render<Kernel, Real, true>(scene, rays, out, context, threads, poll)
                       : vrc::render<Kernel, Real, false>(scene, rays, out, context, threads, poll);
}

template <class Real, class Rays>
bool dispatch(const vrc::Scene& scene, const Rays& rays, Strategy strategy, bool brute_force,
              const vrc::Outputs<Real>& out, const vrc::CastContext& context, unsigned threads, const vrc::Poll& poll) {
    switch (strategy) {
        case Strategy::Auto:  // the fastest exact test measured (benchmarks/runtime_vs_error.py)
        case Strategy::Watertight:
            return render_with<vrc::Watertight, Real>(scene, rays, brute_force, out, context, threads, poll);
        case Strategy::Plane:
            return render_with<vrc::SeedPlane, Real>(scene, rays, brute_force, out, context, threads, poll);
        case Strategy::Cramer:
            return render_with<vrc::SeedCramer, Real>(scene, rays, brute_force, out, context, threads, poll);
        case Strategy::MollerTrumbore:
            return render_with<vrc::MollerTrumbore, Real>(scene, rays, brute_force, out, context, threads, poll);
    }
    throw std::logic_error("unhandled strategy");
}

using AnyArray = nb::ndarray<nb::c_contig, nb::device::cpu>;
using ConstAnyArray = nb::ndarray<nb::ro, nb::c_contig, nb::device::cpu>;
using Frame = nb::ndarray<const double, nb::shape<4, 3>, nb::c_contig, nb::device::cpu>;
using MaskOut = nb::ndarray<uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using CellMap = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

/// A mesh array to gather at the hits, and the output array it goes to (Field).
struct FieldRequest {
    ConstAnyArray values;
    AnyArray out;
    bool per_point;
};

/// One cast: what to cast (a camera, or arrays of rays), the options, the output arrays
/// (unset: not asked for) and the mesh's data the per-hit values come from. Python fills
/// it field by field, so new options do not lengthen a call.
struct Request {
    std::optional<Frame> frame;  ///< camera: rows eye, right, up, backward
    double d = 1, width = 1, height = 1, near = 0, far = HUGE_VAL, shift_x = 0, shift_y = 0;
    int64_t nx = 1, ny = 1;
    bool parallel = false;
    std::optional<Points> origins, directions;  ///< arrays of rays, instead of a camera
    /// > 0: the rays are a sweep (SweepRays) of this many rows, from the one origin in `origins`.
    int64_t sweep_rows = 0;
    double tmin = 0, tmax = HUGE_VAL;
    std::string strategy = "auto", accel = "bvh", precision = "float64";
    bool backface_culling = false;
    bool any_hit = false;  // rays only: whether anything lies in [tmin, tmax], found the quickest way
    int threads = 0;
    std::optional<nb::callable> progress;
    std::optional<IdsOut> triangle_id, cell_id, composite_index;
    std::optional<MaskOut> valid;
    std::optional<AnyArray> depth, barycentric, position, normal;
    std::optional<CellMap> cell_ids, surface_cell_ids, composite_ids;
    bool cells_are_triangles = false;  ///< triangle i came from cell i: cell_ids, surface_cell_ids unread
    bool returns_only = false;         ///< rays only: misses written to depth alone (Outputs::returns_only)
    std::vector<FieldRequest> fields;
};

vrc::Dtype dtype_of(const nb::dlpack::dtype& t) {
    using Code = nb::dlpack::dtype_code;
    const auto is = [&](Code code, int bits) { return t.code == uint8_t(code) && t.bits == bits && t.lanes == 1; };
    if (is(Code::Int, 8)) return vrc::Dtype::i8;
    if (is(Code::UInt, 8)) return vrc::Dtype::u8;
    if (is(Code::Int, 16)) return vrc::Dtype::i16;
    if (is(Code::UInt, 16)) return vrc::Dtype::u16;
    if (is(Code::Int, 32)) return vrc::Dtype::i32;
    if (is(Code::UInt, 32)) return vrc::Dtype::u32;
    if (is(Code::Int, 64)) return vrc::Dtype::i64;
    if (is(Code::UInt, 64)) return vrc::Dtype::u64;
    if (is(Code::Float, 32)) return vrc::Dtype::f32;
    if (is(Code::Float, 64)) return vrc::Dtype::f64;
    throw std::invalid_argument("mesh arrays must be of an integer or floating type");
}

/// Elements per row of an array with `rows` rows (the product of its other dimensions).
template <class Array>
std::size_t row_size(const Array& a, std::size_t rows, const char* name) {
    if (a.ndim() == 0 || a.shape(0) != rows)
        throw std::invalid_argument(std::string(name) + " must have one row per " + (rows ? "element" : "ray"));
    std::size_t size = 1;
    for (std::size_t k = 1; k < a.ndim(); ++k) size *= a.shape(k);
    return size;
}

/// A Real output array of `n` rows of `width` elements, or null when not asked for.
template <class Real>
Real* real_out(const std::optional<AnyArray>& a, std::size_t n, std::size_t width, const char* name) {
    if (!a) return nullptr;
    if (a->dtype() != nb::dtype<Real>() || row_size(*a, n, name) != width)
        throw std::invalid_argument(std::string(name) + " must be a (rays, " + std::to_string(width) +
                                    ") array of the cast's precision");
    return static_cast<Real*>(a->data());
}

/// The request's outputs and mesh data for `n` rays, checked against each other and the scene.
template <class Real>
vrc::Outputs<Real> outputs(const vrc::Scene& scene, const Request& q, std::size_t n) {
    vrc::Outputs<Real> out;
    const auto ids = [&](const std::optional<IdsOut>& a, const char* name) -> int64_t* {
        if (!a) return nullptr;
        if (a->shape(0) != n) throw std::invalid_argument(std::string(name) + " must have one row per ray");
        return a->data();
    };
    out.triangle_id = ids(q.triangle_id, "triangle_id");
    out.cell_id = ids(q.cell_id, "cell_id");
    out.composite_index = ids(q.composite_index, "composite_index");
    if (q.valid) {
        if (q.valid->shape(0) != n) throw std::invalid_argument("valid must have one row per ray");
        out.valid = q.valid->data();
    }
    out.depth = real_out<Real>(q.depth, n, 1, "depth");
    out.barycentric = real_out<Real>(q.barycentric, n, 3, "barycentric");
    out.position = real_out<Real>(q.position, n, 3, "position");
    out.normal = real_out<Real>(q.normal, n, 3, "normal");
    const std::size_t n_tri = scene.n_triangles();
    const auto per_triangle = [&](const std::optional<CellMap>& a, const char* name) -> const int64_t* {
        if (!a || a->shape(0) != n_tri) throw std::invalid_argument(std::string(name) + " must have one row per triangle");
        return a->data();
    };
    out.cells_are_triangles = q.cells_are_triangles;
    if (q.returns_only && !out.depth) throw std::invalid_argument("returns_only needs depth, which tells the misses");
    out.returns_only = q.returns_only;
    if (out.cell_id && !q.cells_are_triangles) out.cell_ids = per_triangle(q.cell_ids, "cell_ids");
    if (out.composite_index) out.composite_ids = per_triangle(q.composite_ids, "composite_ids");
    for (const FieldRequest& f : q.fields) {
        const vrc::Dtype type = dtype_of(f.values.dtype());
        if (f.out.dtype() != f.values.dtype()) throw std::invalid_argument("a field's output must be of its input's type");
        const std::size_t components = row_size(f.out, n, "a field's output");
        if (f.per_point) {
            if (row_size(f.values, scene.input_points, "a point field") != components)
                throw std::invalid_argument("a point field's output must have as many components as the field");
        } else {
            if (q.cells_are_triangles) {
                if (f.values.ndim() == 0 || f.values.shape(0) < n_tri)
                    throw std::invalid_argument("a cell field must have a row per triangle when cells are triangles");
            } else {
                out.surface_cell_ids = per_triangle(q.surface_cell_ids, "surface_cell_ids");
            }
            if (f.values.ndim() == 0 || row_size(f.values, f.values.shape(0), "a cell field") != components)
                throw std::invalid_argument("a cell field's output must have as many components as the field");
        }
        out.fields.push_back({f.values.data(), f.out.data(), type, uint32_t(components), f.per_point, f.values.itemsize() * components});
    }
    return out;
}

/// The camera rays of a request, restricted to what may see the scene.
vrc::CameraRays camera_rays(const vrc::Scene& scene, const Request& q) {
    vrc::CameraSpec spec{};
    for (int k = 0; k < 3; ++k) {
        spec.eye[k] = (*q.frame)(0, k);
        spec.u[k] = (*q.frame)(1, k);
        spec.v[k] = (*q.frame)(2, k);
        spec.w[k] = (*q.frame)(3, k);
    }
    spec.d = q.d, spec.width = q.width, spec.height = q.height, spec.near = q.near, spec.far = q.far;
    spec.shift_x = q.shift_x, spec.shift_y = q.shift_y;
    spec.nx = q.nx, spec.ny = q.ny, spec.parallel = q.parallel;
    if (q.nx < 1 || q.ny < 1) throw std::invalid_argument("nx and ny must be >= 1");
    if (!scene.has_bvh() && q.accel != "none" && !vrc::CameraCast::fits(spec))
        throw std::invalid_argument("a scene built without a BVH casts images of at most " +
                                    std::to_string(vrc::ImageRect::kMaxPixels) + " x " +
                                    std::to_string(vrc::ImageRect::kMaxPixels) + " pixels");
    vrc::CameraRays rays(spec);
    rays.restrict_to(scene.bounds, scene.anchor);
    return rays;
}

/// Casts `rays` into `out` with the GIL released, polling Ctrl-C and `progress`. Returns
/// False if aborted.
template <class Real, class Rays>
bool cast_into(const vrc::Scene& scene, const Rays& rays, const vrc::Outputs<Real>& out, Strategy strategy,
               bool brute_force, const vrc::CastContext& context, unsigned threads,
               const std::optional<nb::callable>& progress) {
    PythonPoll poll{progress};
    bool completed;
    {
        nb::gil_scoped_release release;
        completed = dispatch<Real>(scene, rays, strategy, brute_force, out, context, threads, std::ref(poll));
    }
    if (poll.raised) throw nb::python_error();
    return completed;
}

template <class Real, class Rays>
bool run(const vrc::Scene& scene, const Rays& rays, const Request& q) {
    return cast_into<Real>(scene, rays, outputs<Real>(scene, q, rays.size()), parse_strategy(q.strategy),
                           parse_accel(q.accel), vrc::CastContext{q.backface_culling, q.any_hit},
                           resolve_threads(q.threads), q.progress);
}

template <class Real>
bool cast_as(const vrc::Scene& scene, const Request& q) {
    if (q.frame && q.any_hit) throw std::invalid_argument("any_hit serves rays, not cameras");
    if (q.frame && q.returns_only) throw std::invalid_argument("returns_only serves rays, not cameras");
    if (q.frame) return run<Real>(scene, camera_rays(scene, q), q);
    if (!q.origins || !q.directions) throw std::invalid_argument("a request needs a camera frame or origins and directions");
    if (!scene.has_bvh() && q.accel != "none") throw std::invalid_argument("a scene built without a BVH casts camera rays only");
    if (q.sweep_rows > 0) {
        const int64_t n = int64_t(q.directions->shape(0)), cols = n / q.sweep_rows;
        if (q.origins->shape(0) != 1 || cols * q.sweep_rows != n)
            throw std::invalid_argument("a sweep has one origin and sweep_rows rows of directions");
        return run<Real>(scene, vrc::SweepRays(q.origins->data(), q.directions->data(), q.sweep_rows, cols, q.tmin, q.tmax), q);
    }
    if (q.origins->shape(0) != q.directions->shape(0))
        throw std::invalid_argument("origins and directions must have the same number of rows");
    return run<Real>(scene, vrc::ArrayRays(q.origins->data(), q.directions->data(), q.origins->shape(0), q.tmin, q.tmax), q);
}

/// Scene.intersect's arrays (or occluded's answers, with `any_hit`) for rays (n, 3), or one
/// origin row against n directions, that need none of what the general way (scene.py) does
/// beyond a cast: finite, with nonzero directions whose largest components lie in
/// [`longest[0]`, `longest[1]`) (no shift of t), origins within `limit` of the scene's
/// centre as scene.py's Scale.check_origins bounds them (|component| + `reach`), a scene
/// cast unscaled (no shift of positions). The outputs are made here: a call of a few rays
/// spent most of its time in the general way's Python. `wanted`'s bits ask for
/// triangle_id, cell_id, t, barycentric, position and normal (in that order, as the
/// returned tuple's items; None where not asked for). None when a condition fails; the
/// general way then casts, or raises what is wrong.
nb::object quick_rays(const vrc::Scene& scene, Points origins, Points directions, double tmin, double tmax, double reach,
                      double limit, std::array<double, 2> longest, std::optional<CellMap> cell_ids, unsigned wanted,
                      bool any_hit, bool culling, int threads) {
    // (one origin row against many directions, a sensor's rays, is read as it is, not copied)
    const std::size_t n = directions.shape(0);
    const bool one_origin = origins.shape(0) == 1;
    if (n == 0 || !(origins.shape(0) == n || one_origin) || !scene.has_bvh() || !(tmin >= 0 && tmin <= tmax))
        return nb::none();
    if (cell_ids && cell_ids->shape(0) != scene.n_triangles()) return nb::none();
    const unsigned n_threads = resolve_threads(threads);
    vrc::RayExtent e;
    {
        nb::gil_scoped_release release;
        e = vrc::ray_extent(origins.data(), directions.data(), n, n_threads, one_origin);
    }
    if (!e.finite || !e.nonzero || !(std::max(-e.origin_min, e.origin_max) + reach <= limit) ||
        !(e.longest_min >= longest[0] && e.longest_max < longest[1]))
        return nb::none();
    vrc::Outputs<double> out;
    out.cells_are_triangles = !cell_ids;
    out.cell_ids = cell_ids ? cell_ids->data() : nullptr;
    nb::object arrays[6];
    for (nb::object& a : arrays) a = nb::none();  // (where not asked for)
    const auto make = [&](int bit, auto*& pointer, std::size_t width) {
        using T = std::remove_reference_t<decltype(*pointer)>;
        if (!(wanted >> bit & 1)) return;
        pointer = new T[width * n];
        arrays[bit] = nb::cast(owned_array(pointer, n, width));
    };
    if (any_hit) {
        out.valid = new uint8_t[n];
        arrays[0] = nb::cast(owned_array(out.valid, n, 1));
    } else {
        make(0, out.triangle_id, 1);
        make(1, out.cell_id, 1);
        make(2, out.depth, 1);
        make(3, out.barycentric, 3);
        make(4, out.position, 3);
        make(5, out.normal, 3);
    }
    const vrc::ArrayRays rays(origins.data(), directions.data(), n, tmin, tmax, one_origin);
    cast_into<double>(scene, rays, out, Strategy::Auto, false, vrc::CastContext{culling, any_hit}, n_threads, std::nullopt);
    return nb::make_tuple(arrays[0], arrays[1], arrays[2], arrays[3], arrays[4], arrays[5]);
}

bool cast(const vrc::Scene& scene, const Request& q) {
    if (q.precision == "float64") return cast_as<double>(scene, q);
    if (q.precision == "float32") return cast_as<float>(scene, q);
    throw std::invalid_argument("unknown precision '" + q.precision + "'");
}

}  // namespace

void bind_compositing(nb::module_& m);  // compositing_bindings.cpp

// One source, a module per instruction set (CMakeLists.txt): VRC_MODULE names it.
#define VRC_NB_MODULE(name, variable) NB_MODULE(name, variable)
VRC_NB_MODULE(VRC_MODULE, m) {
    // pvbatch under MPI ends its interpreter without releasing every Python object that
    // holds a core function (VTK's observers, ParaView's proxies), and nanobind then reports
    // them as leaks at exit: nothing a user can act on, the process is ending.
    nb::set_leak_warnings(false);
    m.doc() = "Native core of vtkraycast: BVH build, traversal and intersection kernels.";
    nb::class_<vrc::Scene>(m, "Scene")
        .def(
            "__init__",
            [](vrc::Scene* self, Points points, Triangles triangles, int threads, bool bvh) {
                const std::size_t n_points = points.shape(0), n_tri = triangles.shape(0);
                const uint32_t* tri = triangles.data();
                for (std::size_t i = 0; i < 3 * n_tri; ++i)
                    if (tri[i] >= n_points) throw std::invalid_argument("triangle point index out of range");
                const unsigned n_threads = resolve_threads(threads);
                nb::gil_scoped_release release;
                new (self) vrc::Scene(bvh ? vrc::build_scene(points.data(), n_points, tri, n_tri, n_threads)
                                          : vrc::flat_scene(points.data(), n_points, tri, n_tri));
                self->input_points = n_points;
            },
            "points"_a, "triangles"_a, "threads"_a, "bvh"_a = true,
            "Copies the (n, 3) float64 points and (m, 3) uint32 triangles and builds the BVH (with bvh=False none: "
            "enough for one camera cast).")
        .def_prop_ro("has_bvh", &vrc::Scene::has_bvh)
        .def_prop_ro("n_triangles", &vrc::Scene::n_triangles)
        .def_prop_ro("n_nodes", [](const vrc::Scene& s) { return s.binary_nodes; })
        .def_prop_ro("n_camera_nodes", [](const vrc::Scene& s) { return s.camera.nodes.size(); })
        .def_prop_ro(
            "point_bounds",
            [](const vrc::Scene& s) {
                std::array<double, 6> b{HUGE_VAL, -HUGE_VAL, HUGE_VAL, -HUGE_VAL, HUGE_VAL, -HUGE_VAL};
                for (std::size_t i = 0; i < s.points.size(); i += 3)
                    for (int k = 0; k < 3; ++k) {
                        b[2 * k] = std::min(b[2 * k], s.points[i + k]);
                        b[2 * k + 1] = std::max(b[2 * k + 1], s.points[i + k]);
                    }
                return b;
            },
            "(xmin, xmax, ymin, ymax, zmin, zmax) of the points triangles use (infinite ones when there are none).")
        .def_prop_ro("memory_bytes", &vrc::Scene::memory_bytes,
                     "Bytes held by the BVH, the triangles, the points and the memory kept for camera casts.");
    m.attr("max_binned_pixels") = vrc::ImageRect::kMaxPixels;  // widest image a scene without a BVH casts
    nb::class_<Request>(m, "Request", "One cast's rays, options, output arrays and mesh data (fields left unset: not asked for).")
        .def(nb::init<>())
        .def_rw("frame", &Request::frame, nb::arg().none())
        .def_rw("d", &Request::d)
        .def_rw("width", &Request::width)
        .def_rw("shift_x", &Request::shift_x)
        .def_rw("shift_y", &Request::shift_y)
        .def_rw("height", &Request::height)
        .def_rw("near", &Request::near)
        .def_rw("far", &Request::far)
        .def_rw("nx", &Request::nx)
        .def_rw("ny", &Request::ny)
        .def_rw("parallel", &Request::parallel)
        .def_rw("origins", &Request::origins, nb::arg().none())
        .def_rw("directions", &Request::directions, nb::arg().none())
        .def_rw("sweep_rows", &Request::sweep_rows)
        .def_rw("tmin", &Request::tmin)
        .def_rw("tmax", &Request::tmax)
        .def_rw("strategy", &Request::strategy)
        .def_rw("accel", &Request::accel)
        .def_rw("precision", &Request::precision)
        .def_rw("backface_culling", &Request::backface_culling)
        .def_rw("any_hit", &Request::any_hit)
        .def_rw("threads", &Request::threads)
        .def_rw("progress", &Request::progress, nb::arg().none())
        .def_rw("triangle_id", &Request::triangle_id, nb::arg().none())
        .def_rw("cell_id", &Request::cell_id, nb::arg().none())
        .def_rw("composite_index", &Request::composite_index, nb::arg().none())
        .def_rw("valid", &Request::valid, nb::arg().none())
        .def_rw("depth", &Request::depth, nb::arg().none())
        .def_rw("barycentric", &Request::barycentric, nb::arg().none())
        .def_rw("position", &Request::position, nb::arg().none())
        .def_rw("normal", &Request::normal, nb::arg().none())
        .def_rw("cell_ids", &Request::cell_ids, nb::arg().none())
        .def_rw("composite_ids", &Request::composite_ids, nb::arg().none())
        .def_rw("surface_cell_ids", &Request::surface_cell_ids, nb::arg().none())
        .def_rw("cells_are_triangles", &Request::cells_are_triangles)
        .def_rw("returns_only", &Request::returns_only)
        .def(
            "add_field",
            [](Request& q, ConstAnyArray values, AnyArray out, bool per_point) {
                q.fields.push_back({std::move(values), std::move(out), per_point});
            },
            "values"_a, "out"_a, "per_point"_a,
            "Gathers a mesh array at the hits into `out`: a point array interpolated, a cell array by the hit cell.");
    m.def(
        "intersect_all",
        [](const vrc::Scene& scene, Points origins, Points directions, double tmin, double tmax, int threads,
           bool counts_only) -> nb::object {
            if (origins.shape(0) != directions.shape(0)) throw std::invalid_argument("origins and directions differ in length");
            if (!scene.has_bvh()) throw std::invalid_argument("every crossing needs a scene with a BVH");
            const std::size_t n = origins.shape(0);
            const vrc::ArrayRays rays(origins.data(), directions.data(), n, tmin, tmax);
            const unsigned n_threads = resolve_threads(threads);
            if (counts_only) {  // crossings per ray, and whether one lies at the origin (t = 0)
                auto* counts = new int64_t[n];
                auto* at_origin = new uint8_t[n];
                {
                    nb::gil_scoped_release release;
                    vrc::for_each_crossings(scene, rays, n_threads, [&](unsigned, std::size_t k, const std::vector<vrc::RayHit>& h) {
                        counts[k] = int64_t(h.size());
                        at_origin[k] = !h.empty() && h.front().t == 0;
                    });
                }
                return nb::make_tuple(owned_array(counts, n, 1), owned_array(at_origin, n, 1));
            }
            vrc::CrossingList list;
            {
                nb::gil_scoped_release release;
                list = vrc::list_crossings(scene, rays, n_threads);
            }
            const std::size_t m = list.rows;
            return nb::make_tuple(owned_array(list.splits.release(), n + 1, 1), owned_array(list.ray.release(), m, 1),
                                  owned_array(list.triangle.release(), m, 1), owned_array(list.t.release(), m, 1),
                                  owned_array(list.b.release(), m, 3));
        },
        "scene"_a, "origins"_a, "directions"_a, "tmin"_a, "tmax"_a, "threads"_a, "counts_only"_a,
        "Every surface crossing in [tmin, tmax], by ray then t: (splits, ray, input triangle, t, weights), ray k's "
        "rows splits[k] .. splits[k + 1] - 1; or, "
        "with counts_only, (crossings per ray, whether one is at t = 0).");
    nb::class_<vrc::InsideGrid>(m, "InsideGrid",
                                "Cells over a closed mesh's box answering inside/outside by lookup, or by a short segment to "
                                "the nearest cell holding no triangle (src/inside_grid.hpp).")
        .def(
            "__init__",
            [](vrc::InsideGrid* grid, Points points, Triangles triangles, std::array<double, 3> low,
               std::array<double, 3> high, int per_axis) {
                nb::gil_scoped_release release;
                new (grid) vrc::InsideGrid(points.data(), triangles.data(), triangles.shape(0), low, high, per_axis);
            },
            "points"_a, "triangles"_a, "low"_a, "high"_a, "per_axis"_a)
        .def_prop_ro("usable", &vrc::InsideGrid::usable)
        .def(
            "region_points",
            [](const vrc::InsideGrid& grid) {
                const auto found = grid.region_points();
                auto* out = new double[3 * found.size()];
                for (std::size_t i = 0; i < found.size(); ++i) std::copy(found[i].begin(), found[i].end(), out + 3 * i);
                return owned_array(out, found.size(), 3);
            },
            "A point of each region of cells holding no triangle, to be decided and given to set_inside.")
        .def(
            "set_inside",
            [](vrc::InsideGrid& grid, nb::ndarray<const uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> inside) {
                if (inside.shape(0) != grid.regions()) throw std::invalid_argument("one answer per region");
                grid.set_inside(inside.data());
            },
            "inside"_a)
        .def(
            "classify",
            [](const vrc::InsideGrid& grid, Points points) {
                const std::size_t n = points.shape(0);
                auto* answers = new uint8_t[n];
                std::vector<double> ends;
                {
                    nb::gil_scoped_release release;
                    grid.classify(points.data(), n, answers, ends);
                }
                auto* end_rows = new double[ends.size()];
                std::copy(ends.begin(), ends.end(), end_rows);
                return nb::make_tuple(owned_array(answers, n, 1), owned_array(end_rows, ends.size() / 3, 3));
            },
            "points"_a,
            "(answer per point: 0 outside, 1 inside, 2 / 3 decided by a segment to an end outside / inside; "
            "those segments' ends, in order). Points must be finite.");
    m.def(
        "ray_extent",
        [](Points origins, Points directions, int threads) {
            if (origins.shape(0) != directions.shape(0)) throw std::invalid_argument("origins and directions differ in length");
            vrc::RayExtent e;
            {
                nb::gil_scoped_release release;
                e = vrc::ray_extent(origins.data(), directions.data(), origins.shape(0), resolve_threads(threads));
            }
            return nb::make_tuple(e.finite, e.nonzero, e.origin_min, e.origin_max, e.longest_min, e.longest_max);
        },
        "origins"_a, "directions"_a, "threads"_a,
        "(finite, nonzero directions, least and greatest origin component, least and greatest of the directions' "
        "largest |component|) in one parallel pass.");
    m.def(
        "exit_directions",
        [](Points points, std::array<double, 3> low, std::array<double, 3> high, std::array<double, 3> direction) {
            const std::size_t n = points.shape(0);
            auto* out = new double[3 * n];
            {
                nb::gil_scoped_release release;
                const double* p = points.data();
                for (std::size_t i = 0; i < 3 * n; ++i) {
                    const int c = int(i % 3);
                    out[i] = high[c] - p[i] < p[i] - low[c] ? direction[c] : -direction[c];
                }
            }
            return owned_array(out, n, 3);
        },
        "points"_a, "low"_a, "high"_a, "direction"_a,
        "Per point, `direction` with each component's sign towards the nearer side of the box [low, high] on its "
        "axis: a ray that leaves the box through its nearest face.");
    m.def(
        "take_rows",
        [](std::vector<ConstAnyArray> sources, CellMap rows, std::vector<AnyArray> outputs, int threads) {
            if (sources.size() != outputs.size()) throw std::invalid_argument("take_rows needs an output per source");
            const std::size_t n = rows.shape(0);
            const auto row_bytes = [](const auto& a) {
                std::size_t bytes = a.itemsize();
                for (std::size_t d = 1; d < a.ndim(); ++d) bytes *= a.shape(d);
                return bytes;
            };
            std::size_t least = SIZE_MAX;  // rows of the shortest source
            std::vector<vrc::RowCopy> copies;
            for (std::size_t k = 0; k < sources.size(); ++k) {
                const ConstAnyArray& from = sources[k];
                const AnyArray& to = outputs[k];
                if (from.ndim() == 0 || to.ndim() == 0 || to.shape(0) != n || from.dtype() != to.dtype() ||
                    row_bytes(from) != row_bytes(to))
                    throw std::invalid_argument("take_rows: each output must have a row per index and its source's rows");
                copies.push_back({static_cast<const char*>(from.data()), static_cast<char*>(to.data()), row_bytes(to)});
                least = std::min<std::size_t>(least, from.shape(0));
            }
            for (std::size_t i = 0; i < n && !copies.empty(); ++i)
                if (rows.data()[i] < 0 || std::size_t(rows.data()[i]) >= least)
                    throw std::invalid_argument("take_rows: row index out of range");
            nb::gil_scoped_release release;
            vrc::take_rows(copies, rows.data(), n, resolve_threads(threads));
        },
        "sources"_a, "rows"_a, "outputs"_a, "threads"_a,
        "Writes rows `rows` of each source array into its output (a row per index, the source's row size and "
        "type), on several threads.");
    m.def(
        "orientation_signs",
        [](Points c, Points b, Points o, Points d) {
            const std::size_t n = c.shape(0);
            if (b.shape(0) != n || o.shape(0) != n || d.shape(0) != n)
                throw std::invalid_argument("orientation_signs needs four arrays of the same length");
            auto* out = new int8_t[n];
            for (std::size_t i = 0; i < n; ++i)
                out[i] = int8_t(vrc::exact::orientation(c.data() + 3 * i, b.data() + 3 * i, o.data() + 3 * i, d.data() + 3 * i));
            return owned_array(out, n, 1);
        },
        "c"_a, "b"_a, "o"_a, "d"_a,
        "Per row, the exact sign of det[c - o, b - o, d]: the orientation every kernel settles near-zero edge "
        "functions with (for tests against exact rational arithmetic).");
    m.def(
        "cpu_supports_avx2",
        [] { return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"); },
        "Whether this CPU runs the AVX2 build of the core (AVX2 and FMA).");
    bind_compositing(m);
    m.def("quick_rays", &quick_rays, "scene"_a, "origins"_a, "directions"_a, "tmin"_a, "tmax"_a, "reach"_a, "limit"_a,
          "longest"_a, "cell_ids"_a.none(), "wanted"_a, "any_hit"_a, "culling"_a, "threads"_a,
          "(triangle_id, cell_id, t, barycentric, position, normal), those not wanted None, or with any_hit "
          "(valid, None, ...), of the usual call of Scene.intersect or occluded; None when it needs the general way "
          "(see scene.py).");
    m.def("cast", &cast, "scene"_a, "request"_a,
          "Casts a request's rays (released GIL, all outputs written by the workers). Returns False if aborted.");
}
