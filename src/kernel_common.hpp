// What the ray-triangle kernels share: the cast context, the interface the traversal
// calls, and small vector helpers.
#pragma once

#include <cstddef>
#include <cstdint>

#include "bvh.hpp"

namespace vrc {

/// Per-cast settings every kernel sees.
struct CastContext {
    bool cull_back_faces = false;
    bool any_hit = false;  ///< rays ask whether anything is hit (HitPolicy::any), not what first
};

/// Base of the kernels that test a triangle from its three points: the traversal calls
/// `test(scene, i, ...)` with the leaf-order triangle index, this fetches the points and
/// calls the kernel's `operator()(pa, pb, pc, tmin, tmax, t, b)`.
template <class Kernel>
struct PointKernel {
    template <class Real>
    bool test(const Scene& scene, uint32_t i, double tmin, double tmax, double& t, Real b[3]) const {
        const uint32_t* tri = scene.triangles.data() + 3 * std::size_t(i);
        return static_cast<const Kernel&>(*this)(scene.point(tri[0]), scene.point(tri[1]), scene.point(tri[2]), tmin,
                                                 tmax, t, b);
    }
};

/// p - org computed in double, then rounded to Real: every kernel works in coordinates
/// relative to the ray origin (the eye, for camera rays), whatever the world offset.
/// The ray as the seed's kernels see it: origin at 0 (points are taken relative to
/// `org`), direction rounded to Real once per ray.
template <class Real>
struct RayFrame {
    RayFrame(const Ray& ray, const CastContext& context)
        : org(ray.org), cull(context.cull_back_faces), dir{Real(ray.dir[0]), Real(ray.dir[1]), Real(ray.dir[2])} {}
    const double* org;
    bool cull;
    Real dir[3];
};

template <class Real>
inline void relative(const double* p, const double* org, Real out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = static_cast<Real>(p[k] - org[k]);
}

template <class Real>
inline Real dot(const Real a[3], const Real b[3]) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

template <class Real>
inline void cross(const Real a[3], const Real b[3], Real out[3]) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

template <class Real>
inline void sub(const Real a[3], const Real b[3], Real out[3]) {
    for (int k = 0; k < 3; ++k) out[k] = a[k] - b[k];
}

}  // namespace vrc
