// Python bindings of the native core (the private module vtkraycast._core). Arrays cross
// without copies; dtypes and layouts are fixed by the Python side. The GIL is released
// during every build and cast and re-taken only to report progress and check signals.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/function.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>

#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "kernel_cramer.hpp"
#include "kernel_moller_trumbore.hpp"
#include "kernel_plane.hpp"
#include "kernel_watertight.hpp"
#include "render.hpp"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using Points = nb::ndarray<const double, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using Triangles = nb::ndarray<const uint32_t, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;
using IdsOut = nb::ndarray<int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
template <class Real>
using ValuesOut = nb::ndarray<Real, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
template <class Real>
using TriplesOut = nb::ndarray<Real, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;

unsigned resolve_threads(int threads) {
    if (threads < 0) throw std::invalid_argument("threads must be >= 1 (or None for all cores)");
    return threads == 0 ? std::max(1u, std::thread::hardware_concurrency()) : unsigned(threads);
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
              const vrc::Outputs<Real>& out, bool cull, unsigned threads, const vrc::Poll& poll) {
    const vrc::CastContext context{cull};
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

template <class Real, class Rays>
bool run(const vrc::Scene& scene, const Rays& rays, const std::string& strategy, const std::string& accel, bool cull,
         IdsOut triangle_id,
         std::optional<ValuesOut<Real>> depth, std::optional<TriplesOut<Real>> barycentric, int threads,
         std::optional<nb::callable> progress) {
    const std::size_t n = rays.size();
    if (triangle_id.shape(0) != n || (depth && depth->shape(0) != n) || (barycentric && barycentric->shape(0) != n))
        throw std::invalid_argument("output arrays must have one row per ray");
    const vrc::Outputs<Real> out{triangle_id.data(), depth ? depth->data() : nullptr,
                                 barycentric ? barycentric->data() : nullptr};
    const Strategy s = parse_strategy(strategy);
    const bool brute_force = parse_accel(accel);
    const unsigned n_threads = resolve_threads(threads);
    PythonPoll poll{std::move(progress)};
    bool completed;
    {
        nb::gil_scoped_release release;
        completed = dispatch<Real>(scene, rays, s, brute_force, out, cull, n_threads, std::ref(poll));
    }
    if (poll.raised) throw nb::python_error();
    return completed;
}

template <class Real>
void bind_precision(nb::module_& m) {
    m.def(
        "cast_camera",
        [](const vrc::Scene& scene, nb::ndarray<const double, nb::shape<4, 3>, nb::c_contig> frame, double d,
           double width, double height, double near, double far, int64_t nx, int64_t ny, bool parallel,
           const std::string& strategy, const std::string& accel, bool backface_culling, IdsOut triangle_id,
           std::optional<ValuesOut<Real>> depth, std::optional<TriplesOut<Real>> barycentric, int threads,
           std::optional<nb::callable> progress) {
            vrc::CameraSpec spec{};
            for (int k = 0; k < 3; ++k) {
                spec.eye[k] = frame(0, k);
                spec.u[k] = frame(1, k);
                spec.v[k] = frame(2, k);
                spec.w[k] = frame(3, k);
            }
            spec.d = d;
            spec.width = width;
            spec.height = height;
            spec.near = near;
            spec.far = far;
            spec.nx = nx;
            spec.ny = ny;
            spec.parallel = parallel;
            if (!scene.has_bvh() && accel != "none" && !vrc::CameraCast::fits(spec))
                throw std::invalid_argument("a scene built without a BVH casts images of at most " +
                                            std::to_string(vrc::ImageRect::kMaxPixels) + " x " +
                                            std::to_string(vrc::ImageRect::kMaxPixels) + " pixels");
            vrc::CameraRays rays(spec);
            rays.restrict_to(scene.bounds, scene.anchor);
            return run<Real>(scene, rays, strategy, accel, backface_culling, triangle_id, depth, barycentric,
                             threads, std::move(progress));
        },
        "scene"_a, "frame"_a, "d"_a, "width"_a, "height"_a, "near"_a, "far"_a, "nx"_a, "ny"_a, "parallel"_a,
        "strategy"_a, "accel"_a, "backface_culling"_a, "triangle_id"_a, "depth"_a.none(), "barycentric"_a.none(), "threads"_a,
        "progress"_a.none(),
        "Casts one ray per pixel of a camera (frame rows: eye, right, up, backward). Returns False if aborted.");
    m.def(
        "cast_rays",
        [](const vrc::Scene& scene, Points origins, Points directions, double tmin, double tmax,
           const std::string& strategy, const std::string& accel, bool backface_culling, IdsOut triangle_id,
           std::optional<ValuesOut<Real>> t,
           std::optional<TriplesOut<Real>> barycentric, int threads, std::optional<nb::callable> progress) {
            if (origins.shape(0) != directions.shape(0))
                throw std::invalid_argument("origins and directions must have the same number of rows");
            if (!scene.has_bvh() && accel != "none")
                throw std::invalid_argument("a scene built without a BVH casts camera rays only");
            return run<Real>(scene, vrc::ArrayRays(origins.data(), directions.data(), origins.shape(0), tmin, tmax),
                             strategy, accel, backface_culling, triangle_id, t, barycentric, threads,
                             std::move(progress));
        },
        "scene"_a, "origins"_a, "directions"_a, "tmin"_a, "tmax"_a, "strategy"_a, "accel"_a, "backface_culling"_a,
        "triangle_id"_a, "t"_a.none(),
        "barycentric"_a.none(), "threads"_a, "progress"_a.none(),
        "Casts arbitrary rays ((n, 3) origins and directions). Returns False if aborted.");
}

}  // namespace

NB_MODULE(_core, m) {
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
            },
            "points"_a, "triangles"_a, "threads"_a, "bvh"_a = true,
            "Copies the (n, 3) float64 points and (m, 3) uint32 triangles and builds the BVH (with bvh=False none: "
            "enough for one camera cast).")
        .def_prop_ro("has_bvh", &vrc::Scene::has_bvh)
        .def_prop_ro("n_triangles", &vrc::Scene::n_triangles)
        .def_prop_ro("n_nodes", [](const vrc::Scene& s) { return s.nodes.size(); })
        .def_prop_ro("n_camera_nodes", [](const vrc::Scene& s) { return s.camera.nodes.size(); })
        .def_prop_ro("memory_bytes", &vrc::Scene::memory_bytes,
                     "Bytes held by the BVH, the triangles, the points and the memory kept for camera casts.");
    m.attr("max_binned_pixels") = vrc::ImageRect::kMaxPixels;  // widest image a scene without a BVH casts
    bind_precision<double>(m);
    bind_precision<float>(m);
}
