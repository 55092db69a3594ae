// Single-ray traversal of the eight-wide BVH (wide_bvh.hpp): the eight children's boxes in
// the lanes of one AVX register (two SSE registers in the baseline build), in single
// precision with bounds that never miss a box the ray enters; rays beyond single
// precision's reach test the lanes in double instead.
#pragma once

#include <immintrin.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include <type_traits>
#include <vector>

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
[[gnu::always_inline]] inline Lane8 lanes_add(Lane8 a, Lane8 b) { return _mm256_add_ps(a, b); }
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
[[gnu::always_inline]] inline Lane8 lanes_add(Lane8 a, Lane8 b) { return {_mm_add_ps(a.lo, b.lo), _mm_add_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_sub(Lane8 a, Lane8 b) { return {_mm_sub_ps(a.lo, b.lo), _mm_sub_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_mul(Lane8 a, Lane8 b) { return {_mm_mul_ps(a.lo, b.lo), _mm_mul_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_max(Lane8 a, Lane8 b) { return {_mm_max_ps(a.lo, b.lo), _mm_max_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline Lane8 lanes_min(Lane8 a, Lane8 b) { return {_mm_min_ps(a.lo, b.lo), _mm_min_ps(a.hi, b.hi)}; }
[[gnu::always_inline]] inline void lanes_store(float* p, Lane8 a) {
    _mm_store_ps(p, a.lo);
    _mm_store_ps(p + 4, a.hi);
}
[[gnu::always_inline]] inline unsigned lanes_le(Lane8 a, Lane8 b) {
    return unsigned(_mm_movemask_ps(_mm_cmple_ps(a.lo, b.lo))) | unsigned(_mm_movemask_ps(_mm_cmple_ps(a.hi, b.hi))) << 4;
}
#endif
static_assert(WideNode::kWidth == 8, "a node's lanes are eight floats");

/// Slab tests of a wide node's boxes in float. Conservative as in Ize, "Robust BVH Ray
/// Traversal" (JCGT 2013): the origin relative to the anchor is bounded above where that
/// makes a slab distance smaller and below where larger, so the slab distances (b - o) / d
/// are bounded by exact differences with four roundings (d to float, 1 / d, b - o, the
/// product); the far distance is then widened by 2^-20 > 2 gamma(4). NaN (origin on the
/// slab of a zero direction component) leaves a bound unchanged.
class FloatLanes {
   public:
    /// False when the ray is beyond what float slab distances hold without overflow (origin
    /// more than 2^60 from the anchor, a direction component nonzero but below 2^-60 of the
    /// largest, which is in [1, 2)).
    [[gnu::always_inline]] bool setup(const Ray& ray, const double anchor[3]) {
        // The three axes at once in SSE2 lanes (either build): this runs once per ray, and
        // a small scene's ray meets only two or three nodes.
        const __m128d sign_d = _mm_set1_pd(-0.0);
        const __m128d o01 = _mm_sub_pd(_mm_loadu_pd(ray.org), _mm_loadu_pd(anchor));
        const __m128d o2 = _mm_sub_sd(_mm_load_sd(ray.org + 2), _mm_load_sd(anchor + 2));
        const __m128d d01 = _mm_loadu_pd(ray.dir), d2 = _mm_load_sd(ray.dir + 2);
        const auto unusable = [&](__m128d o, __m128d d) {  // (the unused fourth lane is 0, 0)
            const __m128d far_origin = _mm_cmpnle_pd(_mm_andnot_pd(sign_d, o), _mm_set1_pd(0x1p60));  // (or NaN)
            const __m128d tiny_direction = _mm_and_pd(_mm_cmplt_pd(_mm_andnot_pd(sign_d, d), _mm_set1_pd(0x1p-60)),
                                                      _mm_cmpneq_pd(d, _mm_setzero_pd()));
            return _mm_movemask_pd(_mm_or_pd(far_origin, tiny_direction));
        };
        if (unusable(o01, d01) | unusable(o2, d2)) return false;
        // d > 0: the near slab's distance (lo - o) / d is smallest with o rounded up, the
        // far one's largest with o rounded down; d < 0 the other way round. The exact o lies
        // within one float ulp of o's nearest float f (half an ulp from that rounding, far
        // less from the subtraction's), and f +- margin lies at least an ulp away: outward
        // bounds without the branches of a directed rounding.
        const __m128 sign = _mm_set1_ps(-0.0f);
        const __m128 f = _mm_movelh_ps(_mm_cvtpd_ps(o01), _mm_cvtpd_ps(o2));
        const __m128 d = _mm_movelh_ps(_mm_cvtpd_ps(d01), _mm_cvtpd_ps(d2));
        const __m128 size = _mm_add_ps(_mm_mul_ps(_mm_andnot_ps(sign, f), _mm_set1_ps(0x1p-23f)), _mm_set1_ps(0x1p-126f));
        const __m128 margin = _mm_or_ps(size, _mm_and_ps(sign, d));  // the sign of d
        _mm_store_ps(org_near_, _mm_add_ps(f, margin));
        _mm_store_ps(org_far_, _mm_sub_ps(f, margin));
        _mm_store_ps(inv_, _mm_div_ps(_mm_set1_ps(1.0f), d));
        const int negative = _mm_movemask_ps(d);
        for (int k = 0; k < 3; ++k) {
            near_[k] = k + 3 * (negative >> k & 1);
            far_[k] = k + 3 - 3 * (negative >> k & 1);
        }
        tmin_ = round_down(ray.tmin);
        return true;
    }

    /// Follows the far end of the search, `bound`: boxes beyond it are not entered.
    void set_bound(double bound) {
        const float up = round_up(bound);
        tmax_ = up;
        // Entry distances are lower bounds of the exact ones up to their four roundings
        // (2^-21): a box whose entry lies beyond this may be passed over.
        limit_ = up * (1 + 0x1p-18f);
    }
    /// Whether a box entered at `enter` (as test() gave it) lies wholly beyond the bound.
    [[nodiscard]] bool beyond(float enter) const { return enter > limit_; }

    /// Lanes whose box overlaps [tmin, bound], as bits, and their entry distances (lower
    /// bounds of the exact ones).
    [[gnu::always_inline]] unsigned test(const WideNode& node, float enter[WideNode::kWidth]) const {
        Lane8 t0 = lanes_set(tmin_), t1 = lanes_set(tmax_);
        for (int k = 0; k < 3; ++k) {
            const Lane8 inv = lanes_set(inv_[k]);
            const Lane8 tn = lanes_mul(lanes_sub(lanes_load(node.bounds[near_[k]]), lanes_set(org_near_[k])), inv);
            const Lane8 tf = lanes_mul(lanes_sub(lanes_load(node.bounds[far_[k]]), lanes_set(org_far_[k])), inv);
            t0 = lanes_max(tn, t0);  // (the second operand where either is NaN)
            t1 = lanes_min(tf, t1);
        }
        t1 = lanes_mul(t1, lanes_set(kWiden));
        lanes_store(enter, t0);
        return lanes_le(t0, t1);
    }

   private:
    static constexpr float kWiden = 1.0f + 0x1p-20f;
    // (scalars, broadcast at each test: a search copies its lanes, and 400 bytes of
    // registers' images cost more to copy per ray than the broadcasts per node)
    int near_[3], far_[3];
    alignas(16) float org_near_[4], org_far_[4], inv_[4];  ///< x, y, z (and an unused lane)
    float tmin_ = 0, tmax_ = 0;
    float limit_ = 0;
};

/// The same slab tests in double, lane by lane (BoxTester): any ray. Entry distances are
/// handed on rounded down to float (lower bounds still).
class DoubleLanes {
   public:
    explicit DoubleLanes(const Ray& ray, const double anchor[3]) : boxes_(ray, anchor), tmin_(ray.tmin) {}
    void set_bound(double bound) {
        bound_ = bound;
        limit_ = round_up(bound);
    }
    [[nodiscard]] bool beyond(float enter) const { return enter > limit_; }
    unsigned test(const WideNode& node, float enter[WideNode::kWidth]) const {
        unsigned mask = 0;
        for (int c = 0; c < WideNode::kWidth; ++c) {
            Box box;
            for (int k = 0; k < 3; ++k) {
                box.lo[k] = node.bounds[k][c];
                box.hi[k] = node.bounds[3 + k][c];
            }
            const double t = boxes_.enter(box, tmin_, bound_);
            enter[c] = round_down(t);
            if (t != std::numeric_limits<double>::infinity()) mask |= 1u << c;
        }
        return mask;
    }

   private:
    BoxTester boxes_;
    double tmin_, bound_ = 0;
    float limit_ = 0;
};

/// Where hits go with a policy that keeps none (closest, any).
struct NoSink {
    template <class Real>
    void operator()(uint32_t, double, const Real*) const {}
};

/// Closest hit (or with HitPolicy::any, any hit) along a ray in [tmin, tmax] through the
/// wide BVH, children visited nearest first, a node at a time (`step`), so that several
/// rays' searches can take turns and their memory accesses overlap (trace_rays_interleaved). Ties go
/// to the lowest input triangle index (test_triangle), so the answer is the binary
/// traversal's, whatever the order. The watertight kernel meets only the triangles
/// TriangleFilter leaves (its verdicts are that kernel's); the other strategies meet every
/// triangle, so their own errors stay theirs. The ray must outlive the search. Staged
/// (kStaged), a leaf takes three steps, as interleaved searches want: its point indices
/// asked for, then its points, then its test.
template <template <class> class Kernel, class Real, HitPolicy kPolicy, class Lanes, bool kStaged = false,
          class Sink = NoSink>
class WideSearch {
    static constexpr bool kFiltered = std::is_same_v<Kernel<Real>, Watertight<Real>>;
    static_assert(kPolicy != HitPolicy::all || kFiltered, "every hit is found with the watertight kernel");
    struct NoFilter {};
    using Filter = std::conditional_t<kFiltered, TriangleFilter, NoFilter>;
    /// The kernel and filter of the ray, made at its first leaf: a ray that passes the
    /// scene by meets none, and making them (the shear's three divisions) cost such a ray
    /// as much as its node tests.
    struct LeafTests {
        LeafTests(const Ray& ray, const CastContext& context) : kernel(ray, context), filter(filter_for(ray, kernel)) {}
        static Filter filter_for(const Ray& ray, const Kernel<Real>& kernel) {
            if constexpr (kFiltered)
                return TriangleFilter(ray, kernel.shear());
            else
                return NoFilter{};
        }
        const Kernel<Real> kernel;
        const Filter filter;
    };

   public:
    WideSearch(const Scene& scene, const Ray& ray, const CastContext& context, Lanes lanes, Sink* sink = nullptr)
        : scene_(scene), ray_(ray), context_(context), lanes_(lanes), sink_(sink), bound_(ray.tmax) {
        lanes_.set_bound(bound_);
    }

    /// Tests the next node, pushing the children the ray enters, then pops (pop()); staged,
    /// a step may instead be one of a leaf's. False when the search is over.
    bool step() {
        if constexpr (kStaged) {
            if (leaf_stage_ == 1) {  // the leaf's point indices are in cache: ask for its points
                for (uint32_t i = leaf_.child, end = leaf_.child + leaf_.count; i < end; ++i) scene_.prefetch_points(i);
                leaf_stage_ = 2;
                return true;
            }
            if (leaf_stage_ == 2) {
                leaf_stage_ = 0;
                return !leaf(leaf_.child, leaf_.count) && pop();
            }
        }
        const WideNode& node = scene_.wide[node_];
        ++nodes_;
        alignas(32) float enter[WideNode::kWidth];
        unsigned mask = lanes_.test(node, enter);
        // The entered lanes go on the stack farthest first, so the nearest is popped first.
        // Every hit wanted, any order does; any hit, too: a search stops at the first found,
        // wherever it lies, and sorting cost more than finding a nearer one first saved.
        // Each entered lane's place is counted, not searched for: the entered lanes farther
        // than it, and those as far before it (an insertion sort's compares on the distances
        // defeated the branch predictor); without sorting, those before it. The last placed
        // (the nearest) is gone on to at once: its slot, just above the stack's top, is
        // written but not kept.
        if (!mask) return pop();
#if defined(__AVX2__)
        const __m256 keys = _mm256_blendv_ps(_mm256_set1_ps(-HUGE_VALF), _mm256_load_ps(enter), lane_mask(mask));
#endif
        const std::size_t base = top_;
        const int last = __builtin_popcount(mask) - 1;
        top_ += std::size_t(last);
        int nearest = 0;
        for (unsigned rest = mask; rest; rest &= rest - 1) {
            const int c = __builtin_ctz(rest);
            const unsigned before = mask & ((1u << c) - 1);
            unsigned farther = before;
            if constexpr (kPolicy == HitPolicy::closest) {
#if defined(__AVX2__)
                const __m256 key = _mm256_set1_ps(enter[c]);
                farther = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(keys, key, _CMP_GT_OQ))) |
                          (unsigned(_mm256_movemask_ps(_mm256_cmp_ps(keys, key, _CMP_EQ_OQ))) & before);
#else
                farther = 0;
                for (unsigned m = mask; m; m &= m - 1) {
                    const int d = __builtin_ctz(m);
                    farther |= unsigned(enter[d] > enter[c] || (enter[d] == enter[c] && d < c)) << d;
                }
#endif
            }
            const int place = __builtin_popcount(farther);
            push(node, c, enter[c], base + std::size_t(place));
            nearest = place == last ? c : nearest;
        }
        const After after = take({node.child[nearest], node.count[nearest], enter[nearest]});
        return after == After::pop ? pop() : after == After::step;
    }

    [[nodiscard]] const Hit<Real>& hit() const { return hit_; }
    /// Nodes tested so far: what the search cost.
    [[nodiscard]] unsigned nodes() const { return nodes_; }

   private:
    /// Puts lane c of `node` at stack place `at`, and asks memory for what it leads to: a
    /// node (its bounds span its four cache lines) or a leaf's point indices (chosen
    /// without a branch: whether a lane is a leaf follows no pattern the predictor learns).
    [[gnu::always_inline]] void push(const WideNode& node, int c, float enter, std::size_t at) {
        const uint32_t child = node.child[c], count = node.count[c];
        // (addresses as integers: the one not chosen may lie outside its array)
        const uintptr_t as_node = reinterpret_cast<uintptr_t>(scene_.wide.data()) + sizeof(WideNode) * child;
        const uintptr_t as_leaf = reinterpret_cast<uintptr_t>(scene_.triangles.data()) + 3 * sizeof(uint32_t) * child;
        const char* next = reinterpret_cast<const char*>(count == 0 ? as_node : as_leaf);
        for (int line = 0; line < 4; ++line) prefetch_line(next + 64 * line);
        stack_[at] = {child, count, enter};
    }
#if defined(__AVX2__)
    /// The lanes whose bits are set in `bits`, as all-ones lanes.
    static __m256 lane_mask(unsigned bits) {
        const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        return _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(bits)), bit), bit));
    }
#endif

    /// Pops the next node the ray may meet before the closest hit so far; the leaves popped
    /// on the way are tested, or, staged, the first of them is asked for from memory and
    /// ends the step (the next two steps fetch its points and test it). False when there is
    /// nothing left to test.
    bool pop() {
        for (;;) {
            do {
                if (top_ == 0) return false;
                --top_;
            } while (lanes_.beyond(stack_[top_].enter));
            const After after = take(stack_[top_]);
            if (after != After::pop) return after == After::step;
        }
    }

    struct Pending {
        uint32_t child, count;
        float enter;
    };

    /// What a search does after going on to a node or leaf: its next step (a node to test,
    /// or a staged leaf), pop another, or stop (any hit found).
    enum class After { step, pop, stop };
    After take(const Pending& next) {
        if (next.count == 0) {
            node_ = next.child;
            return After::step;
        }
        if constexpr (kStaged) {
            leaf_ = next;
            leaf_stage_ = 1;
            prefetch_line(scene_.triangles.data() + 3 * std::size_t(next.child));
            prefetch_line(scene_.triangles.data() + 3 * std::size_t(next.child + next.count) - 1);
            return After::step;
        } else {
            return leaf(next.child, next.count) ? After::stop : After::pop;
        }
    }

    /// Tests leaf triangles first .. first + count - 1; true when the search is over (any hit).
    bool leaf(uint32_t first, uint32_t count) {
        if (!tests_) tests_.emplace(ray_, context_);
        const Kernel<Real>& kernel = tests_->kernel;
        const Filter& filter = tests_->filter;
        const double before = bound_;
        const double tmin = ray_.tmin;
        if constexpr (kFiltered) {
            for (uint32_t i = first, end = first + count; i < end; i += 4) {
                for (unsigned m = filter.candidates(scene_, i, std::min(4u, end - i), tmin, bound_); m; m &= m - 1) {
                    const uint32_t k = i + __builtin_ctz(m);
                    if constexpr (kPolicy == HitPolicy::all) {
                        double t;
                        Real b[3];
                        if (kernel.test(scene_, k, tmin, bound_, t, b)) (*sink_)(k, t, b);
                        continue;
                    }
                    test_triangle(kernel, scene_, k, tmin, bound_, hit_);
                    if (kPolicy == HitPolicy::any && hit_.found()) return true;
                }
            }
        } else {
            for (uint32_t i = first, end = first + count; i < end; ++i) {
                test_triangle(kernel, scene_, i, tmin, bound_, hit_);
                if (kPolicy == HitPolicy::any && hit_.found()) return true;
            }
        }
        if (bound_ != before) lanes_.set_bound(bound_);
        return false;
    }

    const Scene& scene_;
    const Ray& ray_;
    const CastContext& context_;
    Lanes lanes_;
    std::optional<LeafTests> tests_;
    Sink* sink_;
    Hit<Real> hit_;
    double bound_;
    uint32_t node_ = 0;  // the next node to test: the root first
    Pending leaf_{};     // the next leaf to test, when leaf_stage_ is not 0
    int leaf_stage_ = 0;
    unsigned nodes_ = 0;
    std::size_t top_ = 0;  // (not int: the stack's uint32_t stores could alias it)
    Pending stack_[WideNode::kWidth * 128];  // (at most seven pushed per level, under 96 levels)
};

/// The traversal for one ray: float lanes when its numbers allow, double lanes otherwise.
/// With HitPolicy::all, `sink(i, t, b)` receives every hit (triangle i in leaf order) and
/// the returned hit is empty. (Every hit needs the filtered watertight kernel.) `nodes`,
/// when given, is advanced by the nodes the search tested: what the ray cost.
template <template <class> class Kernel, class Real, HitPolicy kPolicy = HitPolicy::closest, class Sink = NoSink>
Hit<Real> trace_ray(const Scene& scene, const Ray& ray, const CastContext& context, Sink&& sink = Sink{},
                    unsigned* nodes = nullptr) {
    using S = std::remove_reference_t<Sink>;
    if (scene.wide.empty()) return Hit<Real>{};
    // (the two searches spelt out: folded into one generic lambda, small scenes' rays took
    // about 5 % longer)
    FloatLanes fast;
    if (fast.setup(ray, scene.anchor)) {
        WideSearch<Kernel, Real, kPolicy, FloatLanes, false, S> search(scene, ray, context, fast, &sink);
        while (search.step()) {
        }
        if (nodes) *nodes += search.nodes();
        return search.hit();
    }
    WideSearch<Kernel, Real, kPolicy, DoubleLanes, false, S> search(scene, ray, context, DoubleLanes(ray, scene.anchor),
                                                                      &sink);
    while (search.step()) {
    }
    if (nodes) *nodes += search.nodes();
    return search.hit();
}

/// Scenes whose single-ray data (wide nodes, triangles, points) take this much memory or
/// more are traced several rays at a time (trace_rays_interleaved): beyond the caches
/// their rays wait for memory at every node. One thread, alternated with the ray-at-a-time
/// path on random rays: 0.6x the time on 330 k triangles (22 MB) and the frog, 0.9x on
/// 80 k (5 MB), 1.2x on 20 k (0.7 MB).
constexpr std::size_t kInterleavedBytes = std::size_t(2) << 20;

/// Whether rays `which` of `rays` follow one another closely (a lidar's sweep, an image's
/// rows): consecutive rays' origins within a sixteenth of the scene's size and directions
/// within a sixteenth of a radian, on average over every eighth pair (as telling as every
/// pair, at an eighth of the cost). Such rays may find the scene in the caches one after
/// another, or not (the frog's lidar rays took 1.3x the time in flight, the terrain's
/// 0.7x): for them the cheaper way is measured (CostChooser); others always go in flight.
template <class Rays>
bool coherent(const Scene& scene, const Rays& rays, const std::vector<std::size_t>& which) {
    if (which.size() < 2) return true;
    double size = 0;
    for (int k = 0; k < 3; ++k) size = std::max(size, double(scene.bounds.hi[k]) - double(scene.bounds.lo[k]));
    double spread = 0;
    std::size_t pairs = 0;
    for (std::size_t i = 1; i < which.size(); i += 8, ++pairs) {
        const Ray last = rays.ray(which[i - 1]), ray = rays.ray(which[i]);
        double moved = 0, turned = 0;
        const double a = std::sqrt(dot(ray.dir, ray.dir)), b = std::sqrt(dot(last.dir, last.dir));
        for (int k = 0; k < 3; ++k) {
            moved += std::fabs(ray.org[k] - last.org[k]);
            turned += std::fabs(ray.dir[k] / a - last.dir[k] / b);
        }
        spread += (size > 0 ? moved / size : 0) + turned;
    }
    return spread < double(pairs) / 16;
}

/// Closest (or any) hits of rays `which` of `rays`, handed to `store(k, ray, hit)`: up to
/// kInFlight searches take turns a step at a time, each step ending where the search asks
/// for memory (a node, a leaf's point indices, its points), so that while one waits the
/// others compute: single rays through a scene larger than the caches spend most of their
/// time waiting. The answers are trace_ray's; rays finish in any order. With HitPolicy::all
/// each search in flight has a sink of its own among `sinks` (kInFlight of them), readied
/// for ray k by `sink.start(k, ray)`; `store` then receives it too: `store(k, ray, hit,
/// sink)` (nullptr without sinks). `nodes` as trace_ray's. Sixteen in flight: enough to
/// keep the memory busy for random rays through the frog (fewer were slower, more no faster).
constexpr int kInFlight = 16;
template <template <class> class Kernel, class Real, HitPolicy kPolicy, class Rays, class Store, class Sink = NoSink>
void trace_rays_interleaved(const Scene& scene, const Rays& rays, const std::vector<std::size_t>& which,
                            const CastContext& context, Store&& store, Sink* sinks = nullptr, unsigned* nodes = nullptr) {
    using Search = WideSearch<Kernel, Real, kPolicy, FloatLanes, true, Sink>;
    struct Slot {
        std::size_t k;
        Ray ray;
        std::optional<Search> search;
    };
    Slot slots[kInFlight];
    int active = 0;
    std::size_t next = 0;
    // Fills slot i with the next ray that float lanes serve (the others are traced at once).
    auto refill = [&](int i) {
        Slot& slot = slots[i];
        Sink* sink = sinks ? &sinks[i] : nullptr;
        while (next < which.size()) {
            const std::size_t k = which[next++];
            slot.ray = rays.ray(k);
            if constexpr (!std::is_same_v<Sink, NoSink>) {
                if (sink) sink->start(k, slot.ray);
            }
            FloatLanes fast;
            if (scene.wide.empty() || !fast.setup(slot.ray, scene.anchor)) {
                if constexpr (kPolicy == HitPolicy::all)
                    store(k, slot.ray, trace_ray<Kernel, Real, kPolicy>(scene, slot.ray, context, *sink, nodes), sink);
                else
                    store(k, slot.ray, trace_ray<Kernel, Real, kPolicy>(scene, slot.ray, context, NoSink{}, nodes), sink);
                continue;
            }
            slot.k = k;
            slot.search.emplace(scene, slot.ray, context, fast, sink);
            return true;
        }
        return false;
    };
    for (int i = 0; i < kInFlight; ++i)
        if (refill(i)) ++active;
    while (active > 0) {
        for (int i = 0; i < kInFlight; ++i) {
            Slot& slot = slots[i];
            if (!slot.search || slot.search->step()) continue;
            if (nodes) *nodes += slot.search->nodes();
            store(slot.k, slot.ray, slot.search->hit(), sinks ? &sinks[i] : nullptr);
            slot.search.reset();
            if (!refill(i)) --active;
        }
    }
}

}  // namespace vrc
