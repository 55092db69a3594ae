// Single-ray traversal of the eight-wide BVH (wide_bvh.hpp): the eight children's boxes in
// the lanes of one AVX register (two SSE registers in the baseline build), in single
// precision with bounds that never miss a box the ray enters; rays beyond single
// precision's reach test the lanes in double instead.
#pragma once

#include <immintrin.h>

#include <cmath>
#include <cstdint>
#include <limits>

#include <type_traits>

#include "exact_sign.hpp"
#include "kernel_watertight.hpp"
#include "traverse.hpp"
#include "triangle_filter.hpp"
#include "wide_bvh.hpp"

namespace vrc {

/// Float lanes as wide as a node: one AVX register, or two SSE registers in the baseline
/// build.
#if defined(__AVX__)
using Lane8 = __m256;
[[gnu::always_inline]] inline Lane8 lanes_set(float x) { return _mm256_set1_ps(x); }
[[gnu::always_inline]] inline Lane8 lanes_load(const float* p) { return _mm256_load_ps(p); }
[[gnu::always_inline]] inline Lane8 lanes_sub(Lane8 a, Lane8 b) { return _mm256_sub_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_mul(Lane8 a, Lane8 b) { return _mm256_mul_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_max(Lane8 a, Lane8 b) { return _mm256_max_ps(a, b); }
[[gnu::always_inline]] inline Lane8 lanes_min(Lane8 a, Lane8 b) { return _mm256_min_ps(a, b); }
[[gnu::always_inline]] inline void lanes_store(float* p, Lane8 a) { _mm256_store_ps(p, a); }
[[gnu::always_inline]] inline unsigned lanes_le(Lane8 a, Lane8 b) { return unsigned(_mm256_movemask_ps(_mm256_cmp_ps(a, b, _CMP_LE_OQ))); }
#else
struct Lane8 {
    __m128 lo, hi;
};
[[gnu::always_inline]] inline Lane8 lanes_set(float x) { return {_mm_set1_ps(x), _mm_set1_ps(x)}; }
[[gnu::always_inline]] inline Lane8 lanes_load(const float* p) { return {_mm_load_ps(p), _mm_load_ps(p + 4)}; }
[[gnu::always_inline]] inline Lane8 lanes_sub(Lane8 a, Lane8 b) { return {_mm_sub_ps(a.lo, b.lo), _mm_sub_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_mul(Lane8 a, Lane8 b) { return {_mm_mul_ps(a.lo, b.lo), _mm_mul_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_max(Lane8 a, Lane8 b) { return {_mm_max_ps(a.lo, b.lo), _mm_max_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_min(Lane8 a, Lane8 b) { return {_mm_min_ps(a.lo, b.lo), _mm_min_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline void lanes_store(float* p, Lane8 a) { _mm_store_ps(p, a.lo), _mm_store_ps(p + 4, a.hi); }
[[gnu::always_inline]] inline unsigned lanes_le(Lane8 a, Lane8 b) {
    return unsigned(_mm_movemask_ps(_mm_cmple_ps(a.lo, b.lo))) | unsigned(_mm_movemask_ps(_mm_cmple_ps(a.hi, b.hi))) << 4;
}
#endif
static_assert(WideNode::kWidth == 8, "a node's lanes are eight floats");

/// Slab tests of a wide node's boxes in float. Conservative as in Ize, "Robust BVH Ray
/// Traversal" (JCGT 2013): the origin relative to the anchor is rounded up where that makes
/// a slab distance smaller and down where larger, so the slab distances (b - o) / d are
/// computed from exact differences with four roundings (d to float, 1 / d, b - o, the
/// product); the far distance is then widened by 2^-20 > 2 gamma(4). NaN (origin on the
/// slab of a zero direction component) leaves a bound unchanged.
class FloatLanes {
   public:
    /// False when the ray is beyond what float slab distances hold without overflow (origin
    /// more than 2^60 from the anchor, a direction component nonzero but below 2^-60 of the
    /// largest, which is in [1, 2)).
    bool setup(const Ray& ray, const double anchor[3]) {
        for (int k = 0; k < 3; ++k) {
            double hi, lo;
            exact::two_diff(ray.org[k], anchor[k], hi, lo);
            const double d = ray.dir[k];
            if (!(std::fabs(hi) <= 0x1p60) || (d != 0 && std::fabs(d) < 0x1p-60)) return false;
            const bool negative = std::signbit(d);
            near_[k] = negative ? 3 + k : k;
            far_[k] = negative ? k : 3 + k;
            // d > 0: the near slab's distance (lo - o) / d is smallest with o rounded up,
            // the far one's largest with o rounded down; d < 0 the other way round.
            const float up = round_toward(hi, lo, true), down = round_toward(hi, lo, false);
            org_near_[k] = lanes_set(negative ? down : up);
            org_far_[k] = lanes_set(negative ? up : down);
            inv_[k] = lanes_set(1.0f / static_cast<float>(d));
        }
        tmin_ = lanes_set(round_down(ray.tmin));
        return true;
    }

    /// Lanes whose box overlaps [tmin, bound], as bits, and their entry distances (lower
    /// bounds of the exact ones).
    [[gnu::always_inline]] unsigned test(const WideNode& node, double bound, double enter[WideNode::kWidth]) const {
        Lane8 t0 = tmin_, t1 = lanes_set(round_up(bound));
        for (int k = 0; k < 3; ++k) {
            const Lane8 tn = lanes_mul(lanes_sub(lanes_load(node.bounds[near_[k]]), org_near_[k]), inv_[k]);
            const Lane8 tf = lanes_mul(lanes_sub(lanes_load(node.bounds[far_[k]]), org_far_[k]), inv_[k]);
            t0 = lanes_max(tn, t0);  // (the second operand where either is NaN)
            t1 = lanes_min(tf, t1);
        }
        t1 = lanes_mul(t1, lanes_set(kWiden));
        alignas(32) float entry[WideNode::kWidth];
        lanes_store(entry, t0);
        for (int c = 0; c < WideNode::kWidth; ++c) enter[c] = entry[c];
        return lanes_le(t0, t1);
    }

    /// Whether a box entered at `enter` (as test() gave it) lies wholly beyond `bound`.
    static bool beyond(double enter, double bound) { return enter > bound * (1 + 0x1p-19); }

   private:
    static constexpr float kWiden = 1.0f + 0x1p-20f;
    /// hi + lo (a two-difference) rounded to a float above or below it.
    static float round_toward(double hi, double lo, bool up) {
        const float f = static_cast<float>(hi);
        const double g = f;
        if (up && (g < hi || (g == hi && lo > 0))) return next_float(f, true);
        if (!up && (g > hi || (g == hi && lo < 0))) return next_float(f, false);
        return f;
    }
    int near_[3], far_[3];
    Lane8 org_near_[3], org_far_[3], inv_[3], tmin_;
};

/// The same slab tests in double, lane by lane (BoxTester): any ray.
class DoubleLanes {
   public:
    explicit DoubleLanes(const Ray& ray, const double anchor[3]) : boxes_(ray, anchor), tmin_(ray.tmin) {}
    unsigned test(const WideNode& node, double bound, double enter[WideNode::kWidth]) const {
        unsigned mask = 0;
        for (int c = 0; c < WideNode::kWidth; ++c) {
            Box box;
            for (int k = 0; k < 3; ++k) {
                box.lo[k] = node.bounds[k][c];
                box.hi[k] = node.bounds[3 + k][c];
            }
            enter[c] = boxes_.enter(box, tmin_, bound);
            if (enter[c] != std::numeric_limits<double>::infinity()) mask |= 1u << c;
        }
        return mask;
    }
    static bool beyond(double enter, double bound) { return enter > bound; }

   private:
    BoxTester boxes_;
    double tmin_;
};

/// Where hits go with a policy that keeps none (closest, any).
struct NoSink {
    template <class Real>
    void operator()(uint32_t, double, const Real*) const {}
};

/// Closest hit (or with HitPolicy::any, any hit) along `ray` in [tmin, tmax] through the
/// wide BVH, children visited nearest first. Ties go to the lowest input triangle index
/// (test_triangle), so the answer is the binary traversal's, whatever the order. The
/// watertight kernel meets only the triangles TriangleFilter leaves (its verdicts are that
/// kernel's); the other strategies meet every triangle, so their own errors stay theirs.
template <template <class> class Kernel, class Real, HitPolicy kPolicy, class Lanes, class Sink>
Hit<Real> wide_hit(const Scene& scene, const Ray& ray, const Kernel<Real>& kernel, const Lanes& lanes, Sink& sink) {
    constexpr bool kFiltered = std::is_same_v<Kernel<Real>, Watertight<Real>>;
    static_assert(kPolicy != HitPolicy::all || kFiltered, "every hit is found with the watertight kernel");
    struct NoFilter {};
    const auto filter = [&] {
        if constexpr (kFiltered) return TriangleFilter(ray, kernel.shear());
        else return NoFilter{};
    }();
    Hit<Real> hit;
    double bound = ray.tmax;
    struct Pending {
        uint32_t child, count;
        double enter;
    } stack[WideNode::kWidth * 128];
    int top = 0;
    uint32_t node_index = 0;
    for (;;) {
        const WideNode& node = scene.wide[node_index];
        double enter[WideNode::kWidth];
        unsigned mask = lanes.test(node, bound, enter);
        // Push the entered lanes farthest first (an insertion sort: most nodes have few
        // entered lanes), so the nearest is popped first.
        int order[WideNode::kWidth], n = 0;
        for (; mask; mask &= mask - 1) {
            const int c = __builtin_ctz(mask);
            int at = n++;
            for (; at > 0 && enter[order[at - 1]] < enter[c]; --at) order[at] = order[at - 1];
            order[at] = c;
        }
        for (int i = 0; i < n; ++i) {
            const int c = order[i];
            if (node.count[c] == 0) {  // the whole node: its bounds span its four cache lines
                const char* next = reinterpret_cast<const char*>(&scene.wide[node.child[c]]);
                for (int line = 0; line < 4; ++line) __builtin_prefetch(next + 64 * line);
            }
            stack[top++] = {node.child[c], node.count[c], enter[c]};
        }
        for (;;) {  // pop: leaves are tested here, nodes go back to the top of the loop
            do {
                if (top == 0) return hit;
                --top;
            } while (Lanes::beyond(stack[top].enter, bound));
            const Pending& next = stack[top];
            if (next.count == 0) {
                node_index = next.child;
                break;
            }
            if constexpr (kFiltered) {
                for (uint32_t i = next.child, end = next.child + next.count; i < end; i += 4) {
                    for (unsigned m = filter.candidates(scene, i, std::min(4u, end - i), ray.tmin, bound); m; m &= m - 1) {
                        if constexpr (kPolicy == HitPolicy::all) {
                            double t;
                            Real b[3];
                            const uint32_t k = i + __builtin_ctz(m);
                            if (kernel.test(scene, k, ray.tmin, bound, t, b)) sink(k, t, b);
                            continue;
                        }
                        test_triangle(kernel, scene, i + __builtin_ctz(m), ray.tmin, bound, hit);
                        if (kPolicy == HitPolicy::any && hit.found()) return hit;
                    }
                }
            } else {
                for (uint32_t i = next.child, end = next.child + next.count; i < end; ++i) {
                    test_triangle(kernel, scene, i, ray.tmin, bound, hit);
                    if (kPolicy == HitPolicy::any && hit.found()) return hit;
                }
            }
        }
    }
}

/// The traversal for one ray: float lanes when its numbers allow, double lanes otherwise.
/// With HitPolicy::all, `sink(i, t, b)` receives every hit (triangle i in leaf order) and
/// the returned hit is empty. (Every hit needs the filtered watertight kernel.)
template <template <class> class Kernel, class Real, HitPolicy kPolicy = HitPolicy::closest, class Sink = NoSink>
Hit<Real> trace_ray(const Scene& scene, const Ray& ray, const CastContext& context, Sink&& sink = Sink{}) {
    if (scene.wide.empty()) return Hit<Real>{};
    const Kernel<Real> kernel(ray, context);
    FloatLanes fast;
    if (fast.setup(ray, scene.anchor)) return wide_hit<Kernel, Real, kPolicy>(scene, ray, kernel, fast, sink);
    return wide_hit<Kernel, Real, kPolicy>(scene, ray, kernel, DoubleLanes(ray, scene.anchor), sink);
}

}  // namespace vrc
