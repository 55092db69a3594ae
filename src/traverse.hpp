// What every traversal shares: the conservative box test, the closest-hit rule with its
// ties, and the seed's brute force.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "bvh.hpp"
#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// Ray-box slab test made conservative as in Ize, "Robust BVH Ray Traversal" (JCGT 2013):
/// each slab distance carries at most gamma(4) relative error, so the far distance is
/// widened by 1 + 2 gamma(4). Boxes are relative to the scene's anchor; the ray origin
/// relative to it is kept exactly as two doubles (hi + lo), so the slab distance
/// ((b - hi) - lo) / d has four roundings (gamma(3) in Ize's paper, one more here). NaN slab
/// distances (origin on a slab of a zero direction component) are ignored rather than
/// rejecting the box.
struct BoxTester {
    double org_hi[3], org_lo[3];
    double inv[3];
    int near_is_hi[3];
    static constexpr double kUlp = std::numeric_limits<double>::epsilon() / 2;
    static constexpr double kWiden = 1.0 + 2.0 * (4 * kUlp / (1 - 4 * kUlp));

    BoxTester(const Ray& ray, const double anchor[3]) {
        for (int k = 0; k < 3; ++k) {
            exact::two_diff(ray.org[k], anchor[k], org_hi[k], org_lo[k]);
            inv[k] = 1.0 / ray.dir[k];
            near_is_hi[k] = std::signbit(inv[k]);
        }
    }

    /// Entry distance of the box when it overlaps [tmin, tmax], else +infinity.
    [[nodiscard]] double enter(const Box& box, double tmin, double tmax) const {
        double t0 = tmin, t1 = tmax;
        for (int k = 0; k < 3; ++k) {
            const double lo = near_is_hi[k] ? box.hi[k] : box.lo[k];
            const double hi = near_is_hi[k] ? box.lo[k] : box.hi[k];
            const double tn = ((lo - org_hi[k]) - org_lo[k]) * inv[k];
            const double tf = ((hi - org_hi[k]) - org_lo[k]) * inv[k] * kWiden;
            t0 = tn > t0 ? tn : t0;  // written so that NaN leaves the bound unchanged
            t1 = tf < t1 ? tf : t1;
        }
        return t0 <= t1 ? t0 : std::numeric_limits<double>::infinity();
    }
};

/// Conservative ray-sphere test: false only when the ray's line passes farther than the
/// radius (with a relative margin far above rounding) from the centre, or the sphere lies
/// wholly outside [tmin, tmax].
inline bool may_hit_sphere(const Scene& scene, const Ray& ray) {
    if (scene.sphere_radius < 0) return false;
    double oc[3], dd = 0, od = 0, oo = 0;
    for (int k = 0; k < 3; ++k) {
        oc[k] = scene.sphere_center[k] - ray.org[k];
        dd += ray.dir[k] * ray.dir[k];
        od += oc[k] * ray.dir[k];
        oo += oc[k] * oc[k];
    }
    const double r = scene.sphere_radius * (1 + 1e-9) + 1e-300;
    const double tc = od / dd;                // parameter of the point closest to the centre
    const double miss2 = oo - tc * tc * dd;   // squared distance of the line from the centre
    if (miss2 > r * r * (1 + 1e-9)) return false;
    const double half = std::sqrt(r * r / dd) * (1 + 1e-9);  // parameter half-width of the chord, over-estimated
    return tc + half >= ray.tmin && tc - half <= ray.tmax;
}

/// Hits whose t differ by less than this relative amount (a few dozen roundings of the
/// kernel's precision) are ties: the same point reached through two triangles' own
/// arithmetic (a shared edge, duplicates, coplanar overlaps). A tie goes to the lowest input
/// triangle index, so the winner never depends on traversal order or rounding.
template <class Real>
constexpr double kTieTolerance = 32 * std::numeric_limits<Real>::epsilon();

/// Tests triangle i (leaf order) and keeps it in `hit` when it is closer, or tied with a
/// lower input triangle index; `bound` (the far end of the search) follows the closest hit
/// plus the tie tolerance.
template <class Kernel, class Real>
inline void test_triangle(const Kernel& kernel, const Scene& scene, uint32_t i, double tmin, double& bound,
                          Hit<Real>& hit) {
    double t;
    Real b[3];
    if (!kernel.test(scene, i, tmin, bound, t, b)) return;
    const bool closer = !hit.found() || t < hit.t - kTieTolerance<Real> * std::fabs(hit.t);
    const bool tie_won = !closer && scene.prim_ids[i] < scene.prim_ids[hit.prim];
    if (!closer && !tie_won) return;
    if (closer || t < hit.t) bound = std::min(bound, t + kTieTolerance<Real> * std::fabs(t));
    hit.t = t;
    hit.prim = i;
    // One weight at a time: the kernel stores them one by one, and a wider read across
    // two of those stores (the vectorizer's) waits until both reach the cache.
    for (int c = 0; c < 3; ++c) {
        Real weight = b[c];
        asm("" : "+x"(weight));  // (keeps it a read of its own)
        hit.b[c] = weight;
    }
}

/// What a traversal looks for: the closest hit (ties to the lowest input triangle index),
/// any hit in [tmin, tmax], returned as soon as one is found (occlusion queries), or every
/// hit in [tmin, tmax], each handed to a sink (all_hits.hpp).
enum class HitPolicy { closest, any, all };

/// The seed lecture's method (accel = "none"): the whole model's bounding sphere, then its
/// bounding box, then every triangle. Ties go to the lowest input triangle index.
template <template <class> class Kernel, class Real, HitPolicy kPolicy = HitPolicy::closest>
Hit<Real> brute_force_hit(const Scene& scene, const Ray& ray, const CastContext& context) {
    Hit<Real> hit;
    if (!may_hit_sphere(scene, ray)) return hit;
    if (BoxTester(ray, scene.anchor).enter(scene.bounds, ray.tmin, ray.tmax) == std::numeric_limits<double>::infinity())
        return hit;
    const Kernel<Real> kernel(ray, context);
    double bound = ray.tmax;
    for (uint32_t i = 0, n = uint32_t(scene.n_triangles()); i < n; ++i) {
        test_triangle(kernel, scene, i, ray.tmin, bound, hit);
        if (kPolicy == HitPolicy::any && hit.found()) break;
    }
    return hit;
}

}  // namespace vrc
