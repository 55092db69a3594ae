// Single-ray traversal of the eight-wide BVH (wide_bvh.hpp): the eight children's boxes in
// the lanes of one AVX register (two SSE registers in the baseline build), in single
// precision with bounds that never miss a box the ray enters; rays beyond single
// precision's reach test the lanes in double instead.
#pragma once

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>

#include <type_traits>
#include <vector>

#include "camera_rays.hpp"
#include "cost_chooser.hpp"
#include "kernel_watertight.hpp"
#include "lanes.hpp"
#include "traverse.hpp"
#include "triangle_filter.hpp"
#include "wide_bvh.hpp"

namespace vrc {

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
        // (org[0] and org[1], dir[0] and dir[1] read apart: a ray just made is stored a
        // double at a time, and a read across two stores waits for them to reach the cache)
        const __m128d o01 = _mm_sub_pd(_mm_loadh_pd(_mm_load_sd(ray.org), ray.org + 1), _mm_loadu_pd(anchor));
        const __m128d o2 = _mm_sub_sd(_mm_load_sd(ray.org + 2), _mm_load_sd(anchor + 2));
        const __m128d d01 = _mm_loadh_pd(_mm_load_sd(ray.dir), ray.dir + 1), d2 = _mm_load_sd(ray.dir + 2);
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
        // bounds without the branches of a directed rounding. The margin is at least
        // 2 kTinyBound: f +- margin is then a multiple of 2^-87 as the bounds are (wide_bvh.hpp),
        // so that a difference of the two is 0 or at least 2^-87, never subnormal, nor its
        // product with 1 / d (above 0.5).
        const __m128 sign = _mm_set1_ps(-0.0f);
        const __m128 f = _mm_movelh_ps(_mm_cvtpd_ps(o01), _mm_cvtpd_ps(o2));
        const __m128 d = _mm_movelh_ps(_mm_cvtpd_ps(d01), _mm_cvtpd_ps(d2));
        const __m128 size = _mm_add_ps(_mm_mul_ps(_mm_andnot_ps(sign, f), _mm_set1_ps(0x1p-23f)), _mm_set1_ps(2 * kTinyBound));
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
        tmin_ = tmin_ < kTinyBound ? 0.0f : tmin_;  // (lower still: no subnormal)
        return true;
    }

    /// Follows the far end of the search, `bound`: boxes beyond it are not entered.
    void set_bound(double bound) {
        // (rounded up by a product, not round_up's branches: a bound one float step looser
        // than it need be only widens the test, which the limit below widens far more)
        const float up = std::max(static_cast<float>(bound * (1 + 0x1p-23)), bound > 0 ? kTinyBound : 0.0f);  // (no subnormal)
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
/// (kStaged), a leaf takes two steps after its block and point indices are asked for, as
/// interleaved searches want: the filter, asking for the candidates' points; their test.
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
        LeafTests(const Scene& scene, const Ray& ray, const CastContext& context)
            : kernel(ray, context), filter(filter_for(scene, ray, kernel)) {}
        static Filter filter_for(const Scene& scene, const Ray& ray, const Kernel<Real>& kernel) {
            if constexpr (kFiltered)
                return TriangleFilter(scene, ray, kernel.shear());
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
    [[gnu::always_inline]] bool step() {
        if constexpr (kStaged) {
            if (leaf_stage_ == 1) {  // the leaf's block and point indices are in cache: filter, ask for the candidates' points
                leaf_candidates_ = candidates(leaf_.child, leaf_size(leaf_.count));
                if (kPolicy == HitPolicy::any && hit_.found()) return false;
                if (!leaf_candidates_) {
                    leaf_stage_ = 0;
                    return pop();
                }
                const uint32_t first = scene_.leaf(leaf_.child).first;
                for (unsigned m = leaf_candidates_; m; m &= m - 1) scene_.prefetch_points(first + __builtin_ctz(m));
                leaf_stage_ = 2;
                return true;
            }
            if (leaf_stage_ == 2) {
                leaf_stage_ = 0;
                return !test_leaf(leaf_.child, leaf_candidates_) && pop();
            }
        }
        const WideNode& node = scene_.wide[node_];
        ++nodes_;
        alignas(32) float enter[WideNode::kWidth];
        unsigned mask = lanes_.test(node, enter);
        if (!mask) return pop();
        // The entered lanes go on the stack farthest first, so the nearest is popped first,
        // and the nearest is gone on to at once. Every hit wanted, any order does; any hit,
        // too (a search stops at the first found, wherever it lies), but the order costs
        // little here.
#if defined(__AVX2__)
        // (the sorting network however many lanes were entered: a branch on their number,
        // mostly one or two, was mispredicted about once a ray)
        const int nearest = push_sorted(node, enter, mask);
#else
        int nearest;
        if (__builtin_popcount(mask) <= 2) {  // (most nodes: one lane or two entered)
            const int c0 = __builtin_ctz(mask), c1 = 31 - __builtin_clz(mask);
            // (chosen by masks, not branches: which of the two is nearer follows no pattern)
            const int swap = (c0 ^ c1) & -int(enter[c1] < enter[c0]);
            nearest = c0 ^ swap;
            const int other = c1 ^ swap;  // (one lane: a slot written, not kept)
            stack_child_[top_] = node.child[other], stack_count_[top_] = node.count[other], stack_enter_[top_] = enter[other];
            top_ += std::size_t(c0 != c1);
            prefetch_child(node, other);
        } else {
            nearest = push_sorted(node, enter, mask);
        }
#endif
        const After after = take({node.child[nearest], node.count[nearest], enter[nearest]});
        return after == After::pop ? pop() : after == After::step;
    }

    [[nodiscard]] const Hit<Real>& hit() const { return hit_; }
    /// Nodes tested so far: what the search cost.
    [[nodiscard]] unsigned nodes() const { return nodes_; }

   private:
    /// Pushes the lanes of `mask` (entered at `enter`) but the nearest, farthest first, and
    /// returns the nearest.
    int push_sorted(const WideNode& node, const float enter[WideNode::kWidth], unsigned mask) {
        const std::size_t base = top_;
        top_ += std::size_t(__builtin_popcount(mask) - 1);
#if defined(__AVX2__)
        // Without a branch per lane (whether and where a lane goes follows no pattern the
        // predictor learns): the lanes sorted by a sorting network on keys that carry their
        // lane number, the nearest found apart by a shorter reduction (the next node's load
        // waits for it, not for the sort). Non-negative floats order as their bits; the low
        // three bits of a key give way to the lane, which orders only: the stack keeps the
        // exact entries.
        const __m256 entry = _mm256_load_ps(enter);
        const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        const __m256i bits = _mm256_castps_si256(_mm256_max_ps(entry, _mm256_setzero_ps()));
        const __m256i key = _mm256_blendv_epi8(_mm256_set1_epi32(-1), _mm256_or_si256(_mm256_andnot_si256(_mm256_set1_epi32(7), bits), lane),
                                               _mm256_castps_si256(lane_mask(mask)));
        const __m256i order = _mm256_and_si256(sort_descending(key), _mm256_set1_epi32(7));
        const auto load = [](const uint32_t* p) { return _mm256_load_si256(reinterpret_cast<const __m256i*>(p)); };
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack_child_ + base), _mm256_permutevar8x32_epi32(load(node.child), order));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(stack_count_ + base), _mm256_permutevar8x32_epi32(load(node.count), order));
        _mm256_storeu_ps(stack_enter_ + base, _mm256_permutevar8x32_ps(entry, order));
        return nearest_lane(key);
#else
        // Each lane's place counted: the lanes farther than it, and those as far before it.
        int nearest = 0;
        const std::size_t last = top_;
        for (unsigned rest = mask; rest; rest &= rest - 1) {
            const int c = __builtin_ctz(rest);
            unsigned farther = 0;
            for (unsigned m = mask; m; m &= m - 1) {
                const int d = __builtin_ctz(m);
                farther |= unsigned(enter[d] > enter[c] || (enter[d] == enter[c] && d < c)) << d;
            }
            const std::size_t at = base + std::size_t(__builtin_popcount(farther));
            stack_child_[at] = node.child[c], stack_count_[at] = node.count[c], stack_enter_[at] = enter[c];
            nearest = at == last ? c : nearest;
        }
        return nearest;
#endif
    }

#if defined(__AVX2__)
    /// The lanes whose bits are set in `bits`, as all-ones lanes.
    static __m256 lane_mask(unsigned bits) {
        const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        return _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(bits)), bit), bit));
    }
    /// The lane of the least key (unsigned: the lanes left out, -1, are the greatest).
    [[gnu::always_inline]] static int nearest_lane(__m256i key) {
        __m256i m = _mm256_min_epu32(key, _mm256_shuffle_epi32(key, 0xB1));
        m = _mm256_min_epu32(m, _mm256_shuffle_epi32(m, 0x4E));
        return _mm_cvtsi128_si32(_mm_min_epu32(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1))) & 7;
    }
    /// One layer of a sorting network: each lane against the lane `partner` takes it to,
    /// the greater kept in the lanes whose bits `greater` sets (signed keys).
    template <int kGreater>
    [[gnu::always_inline]] static __m256i exchange(__m256i v, __m256i partner) {
        return _mm256_blend_epi32(_mm256_min_epi32(v, partner), _mm256_max_epi32(v, partner), kGreater);
    }
    /// Eight signed keys in descending order: Batcher's bitonic network (two halves
    /// sorted opposite ways, then merged), six layers.
    [[gnu::always_inline]] static __m256i sort_descending(__m256i v) {
        const auto pairs = [](__m256i x) { return _mm256_shuffle_epi32(x, 0xB1); };   // 1 0 3 2
        const auto twos = [](__m256i x) { return _mm256_shuffle_epi32(x, 0x4E); };    // 2 3 0 1
        const auto halves = [](__m256i x) { return _mm256_permute2x128_si256(x, x, 1); };
        v = exchange<0x99>(v, pairs(v));
        v = exchange<0xC3>(v, twos(v));
        v = exchange<0xA5>(v, pairs(v));
        v = exchange<0x0F>(v, halves(v));
        v = exchange<0x33>(v, twos(v));
        return exchange<0x55>(v, pairs(v));
    }
#endif

    /// Asks memory for what lane c of `node` leads to, a node or a leaf's block, chosen
    /// without a branch (whether a lane is a leaf follows no pattern the predictor learns).
    /// The baseline build asks for the second of two entered lanes when it pushes it: rays
    /// that follow one another through a scene beyond the caches, traced one after another,
    /// then wait less for it, while the sorted pushes of three or more stay cheap for scenes
    /// in the caches.
    [[gnu::always_inline]] void prefetch_child(const WideNode& node, int c) const {
        const uint32_t child = node.child[c];
        // (addresses as integers: the one not chosen may lie outside its array)
        const uintptr_t as_node = reinterpret_cast<uintptr_t>(scene_.wide.data()) + sizeof(WideNode) * child;
        const uintptr_t as_leaf = reinterpret_cast<uintptr_t>(scene_.leaf_bytes.data()) + 4 * std::size_t(child);
        const uintptr_t leaf = -uintptr_t(node.count[c] != 0);  // all ones: a leaf
        prefetch_block(reinterpret_cast<const char*>(as_node ^ ((as_node ^ as_leaf) & leaf)));
    }

    /// Asks memory for a wide node or a leaf's block at `p` (four lines hold either).
    [[gnu::always_inline]] static void prefetch_block(const char* p) {
        static_assert(sizeof(WideNode) == 256 && LeafBlock::bytes(WideNode::kWidth) <= 193, "four lines hold either, wherever it starts");
        for (int line = 0; line < 4; ++line) prefetch_line(p + 64 * line);
    }

    /// Pops the next node the ray may meet before the closest hit so far; the leaves popped
    /// on the way are tested, or, staged, the first of them is asked for from memory and
    /// ends the step (the next two steps fetch its points and test it). False when there is
    /// nothing left to test.
    bool pop() {
        for (;;) {
            do {
                if (top_ == 0) return false;
                --top_;
            } while (lanes_.beyond(stack_enter_[top_]));
            const After after = take({stack_child_[top_], stack_count_[top_], stack_enter_[top_]});
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
            // (staged, other searches' steps come before this node's test)
            if constexpr (kStaged) prefetch_block(reinterpret_cast<const char*>(&scene_.wide[next.child]));
            return After::step;
        }
        if constexpr (kStaged) {
            leaf_ = next;
            leaf_stage_ = 1;
            prefetch_block(reinterpret_cast<const char*>(&scene_.leaf(next.child)));
            prefetch_indices(next.count);
            return After::step;
        } else {
            // (the leaf's filter runs before its point indices are read: time for them to
            // come from the L2 cache or beyond, where a scene's triangles lie when its
            // single-ray data outgrow the L1 cache)
            if (scene_.indices_prefetched) prefetch_indices(next.count);
            return leaf(next.child, leaf_size(next.count)) ? After::stop : After::pop;
        }
    }

    /// Tests the `count` triangles of leaf `index`; true when the search is over (any hit).
    bool leaf(uint32_t index, uint32_t count) {
        const unsigned m = candidates(index, count);
        return (kPolicy == HitPolicy::any && hit_.found()) || test_leaf(index, m);
    }

    /// Asks memory for the point indices of the leaf whose lane's count is `count`.
    [[gnu::always_inline]] void prefetch_indices(uint32_t count) const {
        // (an address as an integer: past the array where the hint is wrong)
        const uintptr_t indices = reinterpret_cast<uintptr_t>(scene_.triangles.data()) + 12 * std::size_t(leaf_first_hint(count));
        prefetch_short(reinterpret_cast<const char*>(indices), 12 * std::size_t(leaf_size(count)));
    }

    /// The leaf's triangles that may meet the ray, as bits: those the filter leaves, or
    /// (other kernels) all. Any hit: a triangle the filter finds surely hit ends the search
    /// here, its points never read (hit_ then holds it, its t and weights not worked out:
    /// an any-hit query reads neither).
    unsigned candidates(uint32_t index, uint32_t count) {
        if (!tests_) tests_.emplace(scene_, ray_, context_);
        if constexpr (kFiltered && kPolicy == HitPolicy::any) {
            const LeafBlock& block = scene_.leaf(index);
            unsigned certain;
            const unsigned m = tests_->filter.template candidates<true>(block, count, bound_, context_.cull_back_faces, &certain);
            if (certain) hit_.prim = block.first + __builtin_ctz(certain);
            return m;
        } else if constexpr (kFiltered) {
            return tests_->filter.candidates(scene_.leaf(index), count, bound_);
        } else {
            return (1u << count) - 1;
        }
    }

    /// Tests the leaf's triangles whose bits `m` holds; true when the search is over (any hit).
    bool test_leaf(uint32_t index, unsigned m) {
        const Kernel<Real>& kernel = tests_->kernel;
        const double before = bound_;
        const double tmin = ray_.tmin;
        const uint32_t first = scene_.leaf(index).first;
        // (a closest hit's store reads its input triangle index first: a scattered read,
        // which in a scene beyond the L2 cache would wait as the search ends; staged
        // searches' stores wait a round of turns for it instead, DeferredStore; asked for
        // whether or not the filter left a triangle: a branch on that would often be
        // mispredicted, and a leaf's input indices mostly share a line)
        if constexpr (kPolicy == HitPolicy::closest && !kStaged)
            prefetch_line(reinterpret_cast<const char*>(scene_.prim_ids.data()) + 4 * (std::size_t(first) + __builtin_ctz(m | 0x100)));
        for (; m; m &= m - 1) {
            const uint32_t k = first + __builtin_ctz(m);
            if constexpr (kPolicy == HitPolicy::all) {
                double t;
                Real b[3];
                if (kernel.test(scene_, k, tmin, bound_, t, b)) (*sink_)(k, t, b);
                continue;
            }
            test_triangle(kernel, scene_, k, tmin, bound_, hit_);
            if (kPolicy == HitPolicy::any && hit_.found()) return true;
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
    unsigned leaf_candidates_ = 0;  // staged: the leaf's triangles its filter left
    unsigned nodes_ = 0;
    std::size_t top_ = 0;  // (not int: the stack's uint32_t stores could alias it)
    // (at most seven pushed per level, under 96 levels; eight more: all eight lanes are stored)
    static constexpr std::size_t kStack = WideNode::kWidth * 129;
    alignas(32) uint32_t stack_child_[kStack], stack_count_[kStack];
    alignas(32) float stack_enter_[kStack];
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

/// Scenes whose single-ray data (wide nodes, leaf blocks, triangles, points) take this
/// much memory or more are traced several rays at a time (trace_rays_interleaved): beyond
/// the caches their rays wait for memory at every node. One thread, alternated with the
/// ray-at-a-time path on random rays: 0.6x the time on 330 k triangles (22 MB) and the
/// frog, 0.9x on 80 k (5 MB), 1.2x on 20 k (0.7 MB).
constexpr std::size_t kInterleavedBytes = std::size_t(2) << 20;

/// Whether rays `which` of `rays` follow one another closely (a lidar's sweep, an image's
/// rows): consecutive rays' origins within a sixteenth of the scene's size and directions
/// within a sixteenth of a radian, on average over every eighth pair (as telling as every
/// pair, at an eighth of the cost). Such rays may find the scene in the caches one after
/// another (rays sweeping the frog), or not (rays grazing the terrain): for them the
/// cheaper way is measured (CostChooser); others always go in flight.
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

/// A store of interleaved searches' hits (trace_rays_interleaved) that can ask the cache
/// for what storing a hit on a triangle reads first (Writer::prefetch): its searches then
/// store a hit one round of turns after asking, not at once: storing at once, every search
/// in flight would wait at each hit for its triangle's input index, a read scattered over
/// the mesh's triangles (in a scene beyond the caches, mostly a miss).
template <class Writer>
struct DeferredStore {
    const Writer& writer;
    template <class Real>
    void operator()(std::size_t k, const Ray& ray, const Hit<Real>& hit, NoSink*) const {
        writer(k, ray, hit);
    }
    void prefetch(uint32_t prim) const { writer.prefetch(prim); }
};
template <class Store>
struct IsDeferred : std::false_type {};
template <class Writer>
struct IsDeferred<DeferredStore<Writer>> : std::true_type {};

/// Closest (or any) hits of rays `which` of `rays`, handed to `store(k, ray, hit)`: up to
/// kInFlight searches take turns a step at a time, each step ending where the search asks
/// for memory (a node, a leaf's block and point indices, its candidates' points), so
/// that while one waits the others compute: single rays through a scene larger than the
/// caches spend most of their time waiting. The answers are trace_ray's; rays finish in any
/// order. With HitPolicy::all each search in flight has a sink of its own among `sinks`
/// (kInFlight of them), readied for ray k by `sink.start(k, ray)`; `store` then receives it
/// too: `store(k, ray, hit, sink)` (nullptr without sinks). `nodes` as trace_ray's.
/// `in_flight` (at most kInFlight) searches take turns. Sixteen keep an AMD EPYC's memory
/// busy for random rays through the frog, where eight leave it idle; an Intel Xeon's cores
/// hold fewer lines in flight (about 12 fill buffers against 22 or more), and there the
/// prefetches of sixteen wait for a free one, so eight are faster: callers measure both
/// (InFlightChooser).
constexpr int kInFlight = 16;
template <template <class> class Kernel, class Real, HitPolicy kPolicy, class Rays, class Store, class Sink = NoSink>
void trace_rays_interleaved(const Scene& scene, const Rays& rays, const std::vector<std::size_t>& which,
                            const CastContext& context, Store&& store, Sink* sinks = nullptr, unsigned* nodes = nullptr,
                            int in_flight = kInFlight) {
    using Search = WideSearch<Kernel, Real, kPolicy, FloatLanes, true, Sink>;
    constexpr bool kDeferred = IsDeferred<std::decay_t<Store>>::value;
    struct Finished {  // a hit whose store waits for a round of turns (DeferredStore)
        std::size_t k;
        Ray ray;
        Hit<Real> hit;
    };
    struct Slot {
        std::size_t k;
        Ray ray;
        std::optional<Search> search;
        std::optional<Finished> finished;
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
            if constexpr (std::is_same_v<Rays, ArrayRays>) {  // (other rays are computed, or in the cache)
                if (next + std::size_t(in_flight / 2) < which.size()) rays.prefetch(which[next + std::size_t(in_flight / 2)]);
            }
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
    in_flight = std::clamp(in_flight, 1, kInFlight);
    for (int i = 0; i < in_flight; ++i)
        if (refill(i)) ++active;
    while (active > 0) {
        for (int i = 0; i < in_flight; ++i) {
            Slot& slot = slots[i];
            if constexpr (kDeferred) {
                if (slot.finished) {
                    store(slot.finished->k, slot.finished->ray, slot.finished->hit, nullptr);
                    slot.finished.reset();
                }
            }
            if (!slot.search || slot.search->step()) continue;
            if (nodes) *nodes += slot.search->nodes();
            const Hit<Real>& hit = slot.search->hit();
            if constexpr (kDeferred) {
                if (hit.found()) {
                    store.prefetch(hit.prim);
                    slot.finished = Finished{slot.k, slot.ray, hit};
                } else {
                    store(slot.k, slot.ray, hit, nullptr);
                }
            } else {
                store(slot.k, slot.ray, hit, sinks ? &sinks[i] : nullptr);
            }
            slot.search.reset();
            if (!refill(i)) --active;
        }
    }
    if constexpr (kDeferred)
        for (Slot& slot : slots)
            if (slot.finished) store(slot.finished->k, slot.finished->ray, slot.finished->hit, nullptr);
}

/// Picks the searches in flight for trace_rays_interleaved, sixteen or eight, by their
/// measured cost per node on this machine (see kInFlight). One per worker.
class InFlightChooser {
   public:
    /// Runs trace(in_flight) with the count picked; trace advances `nodes` by the nodes
    /// its searches test (trace_rays_interleaved's `nodes`), the unit of its cost.
    template <class Trace>
    void run(unsigned& nodes, Trace&& trace) {
        ways_.run([&](bool fewer) {
            const unsigned before = nodes;
            trace(fewer ? kInFlight / 2 : kInFlight);
            return double(nodes - before);
        });
    }

   private:
    CostChooser ways_;
};

}  // namespace vrc
