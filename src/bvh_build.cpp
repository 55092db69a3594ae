// Binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding volume
// hierarchies"): 16 bins on each axis, the cheapest plane or a leaf, triangles counted in
// the single-ray filter's blocks of four (in_blocks). Two passes per node:
// the binning, which also gives the children's boxes and centroid boxes (each bin keeps
// both), and the partition, which reads each triangle's bin from the binning. Triangle
// boxes are computed once, in float relative to the anchor and rounded outward.
// With several threads, the top nodes are split a level at a time by all threads (slices
// binned and partitioned in parallel), then the subtrees below are built by whichever
// thread is free, each into its own node array in depth-first order. The arrays are
// stitched in the order a sequential build allocates nodes, so the tree and its layout do
// not depend on thread timing nor on the thread count (the order of triangles within a
// leaf may), and they are those of the previous, sequential builder (kept at the end of
// this file for targets without AVX2) but for ties in median splits, now broken by id.
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <system_error>
#include <thread>
#include <type_traits>
#include <utility>
#include <vector>

#include "bvh.hpp"

namespace vrc {
/// Triangles as the SAH counts them: in the single-ray filter's blocks of four
/// (triangle_filter.hpp), so that a leaf of five costs as much as one of eight (Embree's
/// builders count their four-wide leaves the same way).
constexpr uint32_t in_blocks(uint32_t n) { return (n + 3) & ~3u; }
}  // namespace vrc

// The builder below needs AVX2 (and BMI1, POPCNT), which the default build enables
// (-march=native, VTKRAYCAST_NATIVE). Other targets get the previous, portable builder at
// the end of this file: the same tree (one thread: the same layout too), built slower.
#if defined(__AVX2__) && defined(__BMI__) && defined(__POPCNT__)
#include <immintrin.h>

namespace vrc {
namespace {

constexpr int kBins = 16;
constexpr uint32_t kMaxLeaf = 8;        // forced split above this many triangles
constexpr float kTraversalCost = 4.0f;  // SAH cost of a node visit, in triangle tests (frog: 4 over 2, camera casts ~9 % fewer instructions, 24 % less memory; 8 as 4)
constexpr uint32_t kMinTopNode = 1u << 15;  // smallest node binned/partitioned by all threads together
constexpr int kMaxSahDepth = 64;  // below this, median splits: depth stays < 96 (traversal stack 128)

/// A triangle's box (relative to the anchor, rounded outward) and its input index; 32 bytes,
/// one aligned 256-bit load. The low corner is stored negated (exact), so that growing a
/// bin is one max over [-lo, hi]. The centroid is computed on the fly: 0.5 * (lo + hi),
/// as hi - (-lo), the same rounding.
struct alignas(32) Ref {
    float nlo[3];
    uint32_t id;
    float hi[3];
    float pad;
};
static_assert(sizeof(Ref) == 32, "refs are meant to be 32 bytes");

inline __m256 load(const Ref& r) {  // lane 3 (the id's bits) zeroed: no denormal operands
    return _mm256_blend_ps(_mm256_load_ps(r.nlo), _mm256_setzero_ps(), 8);
}
inline __m128 low(__m256 v) { return _mm256_castps256_ps128(v); }
inline __m128 high(__m256 v) { return _mm256_extractf128_ps(v, 1); }
inline __m128 negate(__m128 v) { return _mm_xor_ps(v, _mm_set1_ps(-0.0f)); }
inline __m128 centroid(__m256 v) { return _mm_mul_ps(_mm_sub_ps(high(v), low(v)), _mm_set1_ps(0.5f)); }
inline __m128 centroid(__m128 lo, __m128 hi) { return _mm_mul_ps(_mm_add_ps(lo, hi), _mm_set1_ps(0.5f)); }

/// Box in SIMD registers (lane 3 unused). min/max operand order as in Box::grow.
struct VBox {
    __m128 lo = _mm_set1_ps(std::numeric_limits<float>::infinity());
    __m128 hi = _mm_set1_ps(-std::numeric_limits<float>::infinity());
    void grow(__m128 l, __m128 h) {
        lo = _mm_min_ps(l, lo);
        hi = _mm_max_ps(h, hi);
    }
    void grow(const VBox& b) { grow(b.lo, b.hi); }
    void grow(__m128 p) { grow(p, p); }
    [[nodiscard]] Box box() const {
        alignas(16) float l[4], h[4];
        _mm_store_ps(l, lo);
        _mm_store_ps(h, hi);
        Box b;
        for (int k = 0; k < 3; ++k) {
            b.lo[k] = l[k];
            b.hi[k] = h[k];
        }
        return b;
    }
    /// Box::half_area's arithmetic, in the same order: (dx * dy + dy * dz) + dz * dx.
    [[nodiscard]] float half_area() const {
        const __m128 d = _mm_sub_ps(hi, lo);
        if ((_mm_movemask_ps(_mm_cmpge_ps(d, _mm_setzero_ps())) & 7) != 7) return 0.0f;
        const __m128 p = _mm_mul_ps(d, _mm_shuffle_ps(d, d, _MM_SHUFFLE(3, 0, 2, 1)));  // dx*dy, dy*dz, dz*dx
        return (_mm_cvtss_f32(p) + _mm_cvtss_f32(_mm_shuffle_ps(p, p, 1))) + _mm_cvtss_f32(_mm_shuffle_ps(p, p, 2));
    }
};

/// A node to build: triangles [begin, end), their box and the box of their centroids.
struct Task {
    uint32_t begin, end;
    VBox box, cbox;
    int depth;
};

/// Bin index of a centroid on each axis (lanes 0..2); the same arithmetic as a scalar
/// `int((c - lo) * scale)` clamped to [0, n_bins - 1].
struct Binner {
    __m128 clo, scale;  // scale: 0 on an axis with no extent (or an overflowing one)
    __m128i last;
    int n_bins;
    Binner(const VBox& cbox, uint32_t count) {
        n_bins = static_cast<int>(std::min<uint32_t>(kBins, std::max<uint32_t>(4, count)));
        const __m128 extent = _mm_sub_ps(cbox.hi, cbox.lo);
        const __m128 s = _mm_div_ps(_mm_set1_ps(static_cast<float>(n_bins)), extent);
        const __m128 finite = _mm_cmplt_ps(_mm_andnot_ps(_mm_set1_ps(-0.0f), s),
                                           _mm_set1_ps(std::numeric_limits<float>::infinity()));
        const __m128 use = _mm_and_ps(_mm_cmpgt_ps(extent, _mm_setzero_ps()), finite);
        scale = _mm_blend_ps(_mm_and_ps(s, use), _mm_setzero_ps(), 8);
        clo = cbox.lo;
        last = _mm_set1_epi32(n_bins - 1);
    }
    [[nodiscard]] __m128i bin(__m128 c) const {
        const __m128i b = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(c, clo), scale));
        return _mm_min_epi32(_mm_max_epi32(b, _mm_setzero_si128()), last);
    }
};

/// Per-axis bins: boxes and centroid boxes as [-lo, hi] (grown by one max), counts with the
/// axes as lanes. Binning also records each ref's three bin indices (one byte each, in
/// `index[ref]`): the partition then classifies refs from them, 8 at a time.
struct Bins {
    static constexpr uint32_t kTwoSets = 64;
    __m256 box[3][kBins];
    __m256 cbox[3][kBins];
    alignas(16) int32_t count[kBins][4];

    bool centroids;  // with centroid boxes (large nodes; small ones bound their children's after the partition)

    Bins() = default;  // uninitialised: reset() before use
    Bins(int n_bins, bool with_centroids) { reset(n_bins, with_centroids); }
    void reset(int n_bins, bool with_centroids) {
        centroids = with_centroids;
        const __m256 empty = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
        for (int b = 0; b < n_bins; ++b) {
            for (int k = 0; k < 3; ++k) box[k][b] = empty;
            if (centroids)
                for (int k = 0; k < 3; ++k) cbox[k][b] = empty;
            _mm_store_si128(reinterpret_cast<__m128i*>(count[b]), _mm_setzero_si128());
        }
    }
    template <bool kCentroids>
    static void add_indexed(Bins& bins, __m256 v, const int32_t* b) {
        bins.box[0][b[0]] = _mm256_max_ps(v, bins.box[0][b[0]]);
        bins.box[1][b[1]] = _mm256_max_ps(v, bins.box[1][b[1]]);
        bins.box[2][b[2]] = _mm256_max_ps(v, bins.box[2][b[2]]);
        if (kCentroids) {
            const __m128 c = centroid(v);
            const __m256 cv = _mm256_insertf128_ps(_mm256_castps128_ps256(negate(c)), c, 1);
            bins.cbox[0][b[0]] = _mm256_max_ps(cv, bins.cbox[0][b[0]]);
            bins.cbox[1][b[1]] = _mm256_max_ps(cv, bins.cbox[1][b[1]]);
            bins.cbox[2][b[2]] = _mm256_max_ps(cv, bins.cbox[2][b[2]]);
        }
        ++bins.count[b[0]][0];
        ++bins.count[b[1]][1];
        ++bins.count[b[2]][2];
    }
    /// Bins a batch: the bin indices of all its refs first (independent arithmetic), then the
    /// read-modify-writes, whose addresses are then known early (binning ref by ref, the
    /// next ref's bin loads waited on the previous one's index arithmetic). Larger nodes
    /// alternate between two sets of bins: consecutive triangles of a mesh tend to fall in
    /// the same bins, and one bin's update would wait on the previous one's.
    void add(const Ref* refs, uint32_t* index, uint32_t begin, uint32_t end, const Binner& binner) {
        if (centroids)
            add_impl<true>(refs, index, begin, end, binner);
        else
            add_impl<false>(refs, index, begin, end, binner);
    }
    template <bool kCentroids>
    void add_impl(const Ref* refs, uint32_t* index, uint32_t begin, uint32_t end, const Binner& binner) {
        constexpr uint32_t kBatch = 64;
        alignas(16) int32_t bin[kBatch][4];
        const bool two_sets = end - begin >= kTwoSets;
        Bins second;
        if (two_sets) second.reset(binner.n_bins, centroids);
        Bins* other = two_sets ? &second : this;
        for (uint32_t i0 = begin; i0 < end; i0 += kBatch) {
            const uint32_t n = std::min(kBatch, end - i0);
            for (uint32_t i = 0; i < n; ++i) {
                const __m128i b = binner.bin(centroid(load(refs[i0 + i])));
                _mm_store_si128(reinterpret_cast<__m128i*>(bin[i]), b);
                index[i0 + i] = static_cast<uint32_t>(_mm_cvtsi128_si32(_mm_packus_epi16(_mm_packus_epi32(b, b), b)));
            }
            uint32_t i = 0;
            for (; i + 1 < n; i += 2) {
                add_indexed<kCentroids>(*this, load(refs[i0 + i]), bin[i]);
                add_indexed<kCentroids>(*other, load(refs[i0 + i + 1]), bin[i + 1]);
            }
            if (i < n) add_indexed<kCentroids>(*this, load(refs[i0 + i]), bin[i]);
        }
        if (two_sets) merge(*other, binner.n_bins);
    }
    void merge(const Bins& o, int n_bins) {
        for (int b = 0; b < n_bins; ++b) {
            for (int k = 0; k < 3; ++k) box[k][b] = _mm256_max_ps(o.box[k][b], box[k][b]);
            if (centroids)
                for (int k = 0; k < 3; ++k) cbox[k][b] = _mm256_max_ps(o.cbox[k][b], cbox[k][b]);
            for (int k = 0; k < 3; ++k) count[b][k] += o.count[b][k];
        }
    }
};

inline VBox to_vbox(__m256 b) {
    VBox v;
    v.lo = negate(low(b));
    v.hi = high(b);
    return v;
}

struct Split {
    int axis = -1, bin = 0;
    uint32_t n_left = 0;
    VBox left, right;    // the sides' boxes
    VBox cleft, cright;  // and their centroids' boxes
};

/// Box::half_area of three boxes ([-lo, hi]) at once, one per lane, in the same arithmetic.
inline __m128 half_areas(__m256 a, __m256 b, __m256 c) {
    __m128 x = _mm_add_ps(high(a), low(a)), y = _mm_add_ps(high(b), low(b)), z = _mm_add_ps(high(c), low(c));
    __m128 w = _mm_setzero_ps();
    _MM_TRANSPOSE4_PS(x, y, z, w);  // now x = (dx of a, b, c), y = dy..., z = dz...
    const __m128 zero = _mm_setzero_ps();
    const __m128 ok = _mm_and_ps(_mm_and_ps(_mm_cmpge_ps(x, zero), _mm_cmpge_ps(y, zero)), _mm_cmpge_ps(z, zero));
    const __m128 area = _mm_add_ps(_mm_add_ps(_mm_mul_ps(x, y), _mm_mul_ps(y, z)), _mm_mul_ps(z, x));
    return _mm_and_ps(area, ok);
}

/// The cheapest binned SAH plane over all three axes; axis -1 when a leaf is cheaper. The
/// three axes are evaluated together (one per lane), then chosen in the scalar order.
Split best_split(const Bins& bins, const Binner& binner, uint32_t count, const VBox& bounds) {
    const int n_bins = binner.n_bins;
    alignas(16) float cost[kBins][4];
    alignas(16) int32_t n_left[kBins][4], n_right[kBins][4];
    __m128 right_area[kBins];
    const __m256 empty = _mm256_set1_ps(-std::numeric_limits<float>::infinity());
    __m256 a0 = empty, a1 = empty, a2 = empty;
    __m128i n = _mm_setzero_si128();
    for (int b = n_bins - 1; b > 0; --b) {
        a0 = _mm256_max_ps(bins.box[0][b], a0);
        a1 = _mm256_max_ps(bins.box[1][b], a1);
        a2 = _mm256_max_ps(bins.box[2][b], a2);
        n = _mm_add_epi32(n, _mm_load_si128(reinterpret_cast<const __m128i*>(bins.count[b])));
        right_area[b] = half_areas(a0, a1, a2);
        _mm_store_si128(reinterpret_cast<__m128i*>(n_right[b]), n);
    }
    const __m128 inv_area = _mm_set1_ps(1.0f / std::max(bounds.half_area(), 1e-30f));
    const __m128 traversal = _mm_set1_ps(kTraversalCost);
    const auto in_blocks4 = [](__m128i c) {  // (in_blocks, lane by lane)
        return _mm_cvtepi32_ps(_mm_and_si128(_mm_add_epi32(c, _mm_set1_epi32(3)), _mm_set1_epi32(~3)));
    };
    a0 = a1 = a2 = empty;
    n = _mm_setzero_si128();
    for (int b = 0; b < n_bins - 1; ++b) {
        a0 = _mm256_max_ps(bins.box[0][b], a0);
        a1 = _mm256_max_ps(bins.box[1][b], a1);
        a2 = _mm256_max_ps(bins.box[2][b], a2);
        n = _mm_add_epi32(n, _mm_load_si128(reinterpret_cast<const __m128i*>(bins.count[b])));
        _mm_store_si128(reinterpret_cast<__m128i*>(n_left[b]), n);
        const __m128 nr = in_blocks4(_mm_load_si128(reinterpret_cast<const __m128i*>(n_right[b + 1])));
        const __m128 nl = in_blocks4(n);
        const __m128 sum = _mm_add_ps(_mm_mul_ps(half_areas(a0, a1, a2), nl), _mm_mul_ps(right_area[b + 1], nr));
        _mm_store_ps(cost[b], _mm_add_ps(traversal, _mm_mul_ps(sum, inv_area)));
    }
    // The scalar choice: the first (axis-major) of the cheapest valid planes, if cheaper than a
    // leaf. Invalid planes (an empty side, an axis without extent) and NaN costs never win.
    Split best;
    const float leaf_cost = static_cast<float>(in_blocks(count));
    const __m128 axis_ok = _mm_cmpneq_ps(binner.scale, _mm_setzero_ps());
    const __m128 inf = _mm_set1_ps(std::numeric_limits<float>::infinity());
    __m128 min_cost = inf;
    __m128i min_bin = _mm_setzero_si128();
    for (int b = 0; b < n_bins - 1; ++b) {
        const __m128i nl = _mm_load_si128(reinterpret_cast<const __m128i*>(n_left[b]));
        const __m128i nr = _mm_load_si128(reinterpret_cast<const __m128i*>(n_right[b + 1]));
        const __m128 c = _mm_load_ps(cost[b]);
        const __m128 ok = _mm_and_ps(_mm_and_ps(axis_ok, _mm_cmpord_ps(c, c)),
                                     _mm_castsi128_ps(_mm_and_si128(_mm_cmpgt_epi32(nl, _mm_setzero_si128()),
                                                                    _mm_cmpgt_epi32(nr, _mm_setzero_si128()))));
        const __m128 better = _mm_and_ps(ok, _mm_cmplt_ps(c, min_cost));
        min_cost = _mm_blendv_ps(min_cost, c, better);
        min_bin = _mm_blendv_epi8(min_bin, _mm_set1_epi32(b), _mm_castps_si128(better));
    }
    alignas(16) float mc[4];
    alignas(16) int32_t mb[4];
    _mm_store_ps(mc, min_cost);
    _mm_store_si128(reinterpret_cast<__m128i*>(mb), min_bin);
    float best_cost = leaf_cost;
    for (int k = 0; k < 3; ++k)
        if (mc[k] < best_cost) {
            best_cost = mc[k];
            best.axis = k;
            best.bin = mb[k];
        }
    if (best.axis >= 0) {
        __m256 l = empty, r = empty, cl = empty, cr = empty;
        for (int b = 0; b < n_bins; ++b) {
            if (b <= best.bin) {
                l = _mm256_max_ps(bins.box[best.axis][b], l);
                if (bins.centroids) cl = _mm256_max_ps(bins.cbox[best.axis][b], cl);
            } else {
                r = _mm256_max_ps(bins.box[best.axis][b], r);
                if (bins.centroids) cr = _mm256_max_ps(bins.cbox[best.axis][b], cr);
            }
        }
        best.left = to_vbox(l);
        best.right = to_vbox(r);
        best.cleft = to_vbox(cl);
        best.cright = to_vbox(cr);
        best.n_left = static_cast<uint32_t>(n_left[best.bin][best.axis]);
    }
    return best;
}

/// Partitions refs[begin, end) into those whose bin on `axis` (recorded by the binning in
/// `index`) is <= `bin` and the rest. A block partition (after Edelkamp and Weiss 2016,
/// "BlockQuicksort: how branch mispredictions don't affect quicksort"): 64 refs at each end
/// are classified into a bit mask, with no branches, then the misplaced ones are swapped
/// pairwise; only misplaced refs move. The last < 128: a branch-free Lomuto pass.
uint32_t partition(Ref* refs, const uint32_t* index, uint32_t begin, uint32_t end, int axis, int bin) {
    const __m128i shift = _mm_cvtsi32_si128(8 * axis);
    const __m256i limit = _mm256_set1_epi32(bin), byte = _mm256_set1_epi32(0xff);
    auto right_of = [&](uint32_t first) {  // bit k: refs[first + k] goes right
        uint64_t m = 0;
        for (uint32_t q = 0; q < 64; q += 8) {
            const __m256i b = _mm256_and_si256(
                _mm256_srl_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(index + first + q)), shift), byte);
            m |= uint64_t(uint32_t(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpgt_epi32(b, limit))))) << q;
        }
        return m;
    };
    auto swap = [](Ref& a, Ref& b) {
        const __m256 x = _mm256_load_ps(a.nlo), y = _mm256_load_ps(b.nlo);
        _mm256_store_ps(a.nlo, y);
        _mm256_store_ps(b.nlo, x);
    };
    uint32_t i = begin, j = end;  // [begin, i) left, [j, end) right
    uint64_t ml = 0, mr = 0;      // misplaced refs in [i, i + 64) and [j - 64, j), when loaded
    bool has_l = false, has_r = false;
    while (true) {
        if (!has_l || !has_r) {
            if (j - i < 128) break;
            if (!has_l) ml = right_of(i), has_l = true;
            if (!has_r) mr = ~right_of(j - 64), has_r = true;
        }
        for (int n = static_cast<int>(std::min(_mm_popcnt_u64(ml), _mm_popcnt_u64(mr))); n > 0; --n) {
            swap(refs[i + _tzcnt_u64(ml)], refs[j - 64 + _tzcnt_u64(mr)]);
            ml &= ml - 1;
            mr &= mr - 1;
        }
        if (ml == 0) i += 64, has_l = false;
        if (mr == 0) j -= 64, has_r = false;
    }
    uint32_t left[128];
    for (uint32_t p = i; p < j; ++p) {
        if (has_l && p < i + 64)
            left[p - i] = static_cast<uint32_t>(((ml >> (p - i)) & 1) ^ 1);
        else if (has_r && p >= j - 64)
            left[p - i] = static_cast<uint32_t>((mr >> (p - (j - 64))) & 1);
        else
            left[p - i] = static_cast<uint32_t>(static_cast<int>((index[p] >> (8 * axis)) & 0xff) <= bin);
    }
    uint32_t k = i;
    for (uint32_t p = i; p < j; ++p) {
        swap(refs[p], refs[k]);
        k += left[p - i];
    }
    return k;
}

void bounds_of(const Ref* refs, uint32_t begin, uint32_t end, VBox& box, VBox& cbox) {
    for (uint32_t i = begin; i < end; ++i) {
        const __m256 v = load(refs[i]);
        box.grow(negate(low(v)), high(v));
        cbox.grow(centroid(v));
    }
}

/// Object median along the widest centroid axis: always splits in two halves.
uint32_t median(Ref* refs, const Task& t) {
    const Box c = t.cbox.box();
    int axis = 0;
    for (int k = 1; k < 3; ++k)
        if (c.hi[k] - c.lo[k] > c.hi[axis] - c.lo[axis]) axis = k;
    const uint32_t mid = t.begin + (t.end - t.begin) / 2;
    // Ties broken by id: the halves do not depend on the refs' order (which the parallel
    // partition of the top nodes changes), so neither does the tree.
    std::nth_element(refs + t.begin, refs + mid, refs + t.end, [axis](const Ref& a, const Ref& b) {
        const float ca = 0.5f * (a.hi[axis] - a.nlo[axis]), cb = 0.5f * (b.hi[axis] - b.nlo[axis]);
        return ca < cb || (ca == cb && a.id < b.id);
    });
    return mid;
}

/// An uninitialised buffer (no zero fill: fresh memory showed in profiles), huge pages asked.
template <class T>
std::unique_ptr<T[]> scratch(std::size_t n) {
    std::unique_ptr<T[]> p(new T[n]);
    advise_huge(p.get(), n * sizeof(T));
    return p;
}

/// Runs job(0) .. job(n_jobs - 1) on up to `threads` threads (the calling one included),
/// each taking the next job not taken. The helpers are detached, and the caller waits only
/// for the jobs they took: on a busy machine, a helper that is not scheduled soon costs
/// nothing (the caller does its share), where a join would wait for it.
template <class F>
void run_jobs(unsigned threads, std::size_t n_jobs, F&& job) {
    if (threads <= 1 || n_jobs <= 1) {
        for (std::size_t k = 0; k < n_jobs; ++k) job(k);
        return;
    }
    struct State {
        std::atomic<std::size_t> next{0}, done{0};
        std::size_t n = 0;
        void* job = nullptr;
        void (*call)(void*, std::size_t) = nullptr;
        void work() {
            for (std::size_t k; (k = next.fetch_add(1)) < n;) {
                call(job, k);
                done.fetch_add(1, std::memory_order_release);
            }
        }
    };
    auto state = std::make_shared<State>();  // outlives the call: a late helper only reads `next`
    state->n = n_jobs;
    state->job = &job;
    state->call = [](void* f, std::size_t k) { (*static_cast<std::remove_reference_t<F>*>(f))(k); };
    const auto helpers = static_cast<unsigned>(std::min<std::size_t>(threads, n_jobs)) - 1;
    for (unsigned t = 0; t < helpers; ++t) {
        try {
            std::thread([state] { state->work(); }).detach();
        } catch (const std::system_error&) {
            break;  // no thread: the caller does the jobs
        }
    }
    state->work();
    while (state->done.load(std::memory_order_acquire) < n_jobs) std::this_thread::yield();
}

inline uint32_t slice(uint32_t begin, uint32_t end, unsigned t, unsigned n) {
    return begin + static_cast<uint32_t>((uint64_t(end - begin) * t) / n);
}

/// The split of one node (binned SAH, or a median split), its triangles partitioned.
/// Returns false for a leaf; otherwise fills the two children's tasks.
bool split_node(Ref* refs, uint32_t* index, const Task& t, Task& left, Task& right) {
    const uint32_t count = t.end - t.begin;
    uint32_t mid = t.begin;
    bool split = false;
    if (t.depth >= kMaxSahDepth) {
        mid = median(refs, t);  // down to single triangles, as the sequential builder
    } else if (static_cast<float>(count) > kTraversalCost) {  // else no split can cost less than a leaf
        const Binner binner(t.cbox, count);
        Bins bins(binner.n_bins, count >= Bins::kTwoSets);
        bins.add(refs, index, t.begin, t.end, binner);
        const Split s = best_split(bins, binner, count, t.box);
        if (s.axis >= 0) {
            mid = partition(refs, index, t.begin, t.end, s.axis, s.bin);
            left.box = s.left;
            right.box = s.right;
            if (bins.centroids) {
                left.cbox = s.cleft;
                right.cbox = s.cright;
            } else {
                left.cbox = right.cbox = VBox{};
                for (uint32_t i = t.begin; i < mid; ++i) left.cbox.grow(centroid(load(refs[i])));
                for (uint32_t i = mid; i < t.end; ++i) right.cbox.grow(centroid(load(refs[i])));
            }
            split = true;
        } else if (count > kMaxLeaf) {
            mid = median(refs, t);
        }
    }
    if (!split) {
        if (mid == t.begin || mid == t.end) return false;  // a leaf (count <= kMaxLeaf here)
        left = Task{};
        right = Task{};
        bounds_of(refs, t.begin, mid, left.box, left.cbox);
        bounds_of(refs, mid, t.end, right.box, right.cbox);
    }
    left.begin = t.begin;
    left.end = right.begin = mid;
    right.end = t.end;
    left.depth = right.depth = t.depth + 1;
    return true;
}

/// Splits the nodes of one level of the top of the tree, all threads on each node: every
/// node cut into slices (a fixed number, whichever thread takes them: the result does not
/// depend on the threads), each slice binned, the bins merged; each slice partitioned,
/// then the right-side runs left of the node's split and the left-side runs right of it
/// (as many refs each) swapped pairwise. Three joins per level, not per node.
void split_level(Ref* refs, uint32_t* index, const std::vector<Task>& tasks, unsigned threads, std::vector<char>& is_split,
                 std::vector<Task>& lefts, std::vector<Task>& rights) {
    const std::size_t m = tasks.size();
    const unsigned n_slices = 4 * threads;
    auto bounds = [&](std::size_t job, uint32_t& b, uint32_t& e) {
        const Task& t = tasks[job / n_slices];
        b = slice(t.begin, t.end, static_cast<unsigned>(job % n_slices), n_slices);
        e = slice(t.begin, t.end, static_cast<unsigned>(job % n_slices) + 1, n_slices);
    };
    std::vector<Binner> binners;
    std::vector<char> sah(m);
    for (std::size_t j = 0; j < m; ++j) {
        binners.emplace_back(tasks[j].cbox, tasks[j].end - tasks[j].begin);
        sah[j] = tasks[j].depth < kMaxSahDepth && static_cast<float>(tasks[j].end - tasks[j].begin) > kTraversalCost;
    }
    std::vector<Bins> bins(m * n_slices);
    run_jobs(threads, m * n_slices, [&](std::size_t job) {
        const std::size_t j = job / n_slices;
        if (!sah[j]) return;
        uint32_t b, e;
        bounds(job, b, e);
        bins[job].reset(binners[j].n_bins, true);
        bins[job].add(refs, index, b, e, binners[j]);
    });
    std::vector<Split> splits(m);
    for (std::size_t j = 0; j < m; ++j) {
        if (!sah[j]) continue;
        for (unsigned q = 1; q < n_slices; ++q) bins[j * n_slices].merge(bins[j * n_slices + q], binners[j].n_bins);
        splits[j] = best_split(bins[j * n_slices], binners[j], tasks[j].end - tasks[j].begin, tasks[j].box);
    }
    std::vector<uint32_t> mids(m * n_slices);
    run_jobs(threads, m * n_slices, [&](std::size_t job) {
        const Split& s = splits[job / n_slices];
        if (s.axis < 0) return;
        uint32_t b, e;
        bounds(job, b, e);
        mids[job] = partition(refs, index, b, e, s.axis, s.bin);
    });
    using Runs = std::vector<std::pair<uint32_t, uint32_t>>;
    std::vector<Runs> wrong_r(m), wrong_l(m);
    std::vector<uint64_t> n_wrong(m, 0);
    for (std::size_t j = 0; j < m; ++j) {
        if (splits[j].axis < 0) continue;
        const uint32_t mid = tasks[j].begin + splits[j].n_left;
        for (unsigned q = 0; q < n_slices; ++q) {
            uint32_t b, e;
            bounds(j * n_slices + q, b, e);
            const uint32_t pm = mids[j * n_slices + q];
            if (pm < mid) wrong_r[j].emplace_back(pm, std::min(e, mid));
            if (pm > mid) wrong_l[j].emplace_back(std::max(b, mid), pm);
        }
        for (auto& r : wrong_r[j]) n_wrong[j] += r.second - r.first;
    }
    auto locate = [](const Runs& runs, uint64_t k, std::size_t& run, uint32_t& pos) {
        run = 0;
        while (k >= runs[run].second - runs[run].first) {
            k -= runs[run].second - runs[run].first;
            ++run;
        }
        pos = runs[run].first + static_cast<uint32_t>(k);
    };
    run_jobs(threads, m * n_slices, [&](std::size_t job) {
        const std::size_t j = job / n_slices;
        const unsigned q = static_cast<unsigned>(job % n_slices);
        const uint64_t k0 = n_wrong[j] * q / n_slices, k1 = n_wrong[j] * (q + 1) / n_slices;
        if (k0 == k1) return;
        const Runs &wr = wrong_r[j], &wl = wrong_l[j];
        std::size_t ra, rb;
        uint32_t a, b;
        locate(wr, k0, ra, a);
        locate(wl, k0, rb, b);
        for (uint64_t k = k0; k < k1;) {
            if (a == wr[ra].second) a = wr[++ra].first;
            if (b == wl[rb].second) b = wl[++rb].first;
            const auto n = static_cast<uint32_t>(std::min<uint64_t>({k1 - k, wr[ra].second - a, wl[rb].second - b}));
            std::swap_ranges(refs + a, refs + a + n, refs + b);
            a += n;
            b += n;
            k += n;
        }
    });
    for (std::size_t j = 0; j < m; ++j) {
        const Task& t = tasks[j];
        const Split& s = splits[j];
        if (s.axis < 0) {  // depth limit, or no SAH split: as the sequential builder
            is_split[j] = split_node(refs, index, t, lefts[j], rights[j]);
            continue;
        }
        Task& left = lefts[j];
        Task& right = rights[j];
        left.box = s.left;
        right.box = s.right;
        left.cbox = s.cleft;
        right.cbox = s.cright;
        left.begin = t.begin;
        left.end = right.begin = t.begin + s.n_left;
        right.end = t.end;
        left.depth = right.depth = t.depth + 1;
        is_split[j] = 1;
    }
}

/// Builds a subtree sequentially into `nodes` (its root at nodes[at]), allocating sibling
/// pairs in depth-first order.
void build_subtree(Ref* refs, uint32_t* index, std::vector<Node>& nodes, uint32_t at, const Task& t) {
    Task left, right;
    nodes[at].box = t.box.box();
    if (!split_node(refs, index, t, left, right)) {
        nodes[at].index = t.begin;
        nodes[at].count = t.end - t.begin;
        return;
    }
    const auto pair = static_cast<uint32_t>(nodes.size());
    nodes[at].index = pair;
    nodes[at].count = 0;
    nodes.emplace_back();
    nodes.emplace_back();
    build_subtree(refs, index, nodes, pair, left);
    build_subtree(refs, index, nodes, pair + 1, right);
}

/// float lo/hi of a point relative to the anchor (rounded outward).
struct PointBox {
    float lo[4];
    float hi[4];
};

}  // namespace

Scene build_scene(const double* points, std::size_t n_points, const uint32_t* triangles, std::size_t n_triangles,
                  unsigned threads) {
    Scene scene;
    const unsigned n_threads = std::max(1u, threads);
    if (n_triangles == 0) return scene;
    const uint32_t n = static_cast<uint32_t>(n_triangles);
    // Fewer threads for small meshes: a thread start costs about as much as ~10^4 triangles.
    const unsigned pthreads = static_cast<unsigned>(std::min<std::size_t>(n_threads, 1 + n_triangles / 16384));
    const unsigned chunks = pthreads == 1 ? 1 : 8 * pthreads;  // of the passes over triangles or points

    // The anchor: the centre of the triangles' bounding box, in double.
    std::vector<std::array<double, 6>> part_bounds(chunks);
    run_jobs(pthreads, chunks, [&](std::size_t t) {
        double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
        const std::size_t e = 3 * std::size_t(slice(0, n, t + 1, chunks));
        for (std::size_t i = 3 * std::size_t(slice(0, n, t, chunks)); i < e; ++i) {
            const double* p = points + 3 * std::size_t(triangles[i]);
            for (int k = 0; k < 3; ++k) {
                lo[k] = std::min(lo[k], p[k]);
                hi[k] = std::max(hi[k], p[k]);
            }
        }
        for (int k = 0; k < 3; ++k) {
            part_bounds[t][k] = lo[k];
            part_bounds[t][3 + k] = hi[k];
        }
    });
    double lo_all[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi_all[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
    for (const auto& b : part_bounds)
        for (int k = 0; k < 3; ++k) {
            lo_all[k] = std::min(lo_all[k], b[k]);
            hi_all[k] = std::max(hi_all[k], b[3 + k]);
        }
    for (int k = 0; k < 3; ++k) scene.anchor[k] = 0.5 * lo_all[k] + 0.5 * hi_all[k];
    for (int k = 0; k < 3; ++k) scene.sphere_center[k] = scene.anchor[k];

    // Each point's float box relative to the anchor, rounded outward. relative_down (up) is
    // the largest (smallest) float below (above) the exact difference, a monotonic function
    // of the coordinate: a triangle's float box is the float box of its points' boxes.
    // Also each point's squared distance to the sphere's centre (the anchor).
    auto pbox = scratch<PointBox>(n_points);
    auto pdist = scratch<double>(n_points);
    run_jobs(pthreads, chunks, [&](std::size_t t) {
        const auto np = static_cast<uint32_t>(n_points);
        for (uint32_t i = slice(0, np, t, chunks), e = slice(0, np, t + 1, chunks); i < e; ++i) {
            const double* p = points + 3 * std::size_t(i);
            double d2 = 0;
            for (int k = 0; k < 3; ++k) {
                pbox[i].lo[k] = relative_down(p[k], scene.anchor[k]);
                pbox[i].hi[k] = relative_up(p[k], scene.anchor[k]);
                d2 += (p[k] - scene.sphere_center[k]) * (p[k] - scene.sphere_center[k]);
            }
            pbox[i].lo[3] = pbox[i].hi[3] = 0.0f;
            pdist[i] = d2;
        }
    });

    // The triangles' refs, the root's box and centroid box, the sphere's radius.
    // 2 MiB aligned, and transparent huge pages asked for: far fewer page faults.
    const std::size_t refs_bytes = (sizeof(Ref) * n_triangles + (std::size_t(2) << 20) - 1) & ~((std::size_t(2) << 20) - 1);
    auto* refs = static_cast<Ref*>(std::aligned_alloc(std::size_t(2) << 20, refs_bytes));
    if (refs == nullptr) throw std::bad_alloc();
    advise_huge(refs, refs_bytes);
    std::unique_ptr<Ref, void (*)(void*)> refs_owner(refs, std::free);
    std::vector<Task> part_root(chunks);
    std::vector<double> part_r2(chunks, 0.0);
    run_jobs(pthreads, chunks, [&](std::size_t t) {
        VBox box, cbox;
        double r2 = 0;
        for (uint32_t i = slice(0, n, t, chunks), e = slice(0, n, t + 1, chunks); i < e; ++i) {
            const uint32_t* tri = triangles + 3 * std::size_t(i);
            __m128 lo = _mm_loadu_ps(pbox[tri[0]].lo), hi = _mm_loadu_ps(pbox[tri[0]].hi);
            for (int c = 1; c < 3; ++c) {
                lo = _mm_min_ps(_mm_loadu_ps(pbox[tri[c]].lo), lo);
                hi = _mm_max_ps(_mm_loadu_ps(pbox[tri[c]].hi), hi);
                r2 = std::max(r2, pdist[tri[c]]);
            }
            r2 = std::max(r2, pdist[tri[0]]);
            Ref& r = refs[i];
            _mm_store_ps(r.nlo, negate(lo));
            _mm_store_ps(r.hi, hi);
            r.id = i;
            box.grow(lo, hi);
            cbox.grow(centroid(lo, hi));
        }
        part_root[t].box = box;
        part_root[t].cbox = cbox;
        part_r2[t] = r2;
    });
    Task root{0, n, VBox{}, VBox{}, 0};
    double r2 = 0;
    for (unsigned t = 0; t < chunks; ++t) {
        root.box.grow(part_root[t].box);
        root.cbox.grow(part_root[t].cbox);
        r2 = std::max(r2, part_r2[t]);
    }
    scene.sphere_radius = std::sqrt(r2);
    pbox.reset();
    pdist.reset();

    // The top of the tree, each node split by all threads; nodes below top_min (at least
    // 1/8 of a thread's share) become subtrees for one thread each.
    struct Top {
        Task task;
        int32_t left = -1;    // its children: tops[left], tops[left + 1]
        int32_t subtree = -1;  // or: built as subtrees[subtree]
        bool leaf = false;
    };
    const uint32_t top_min = std::max<uint32_t>(kMinTopNode, n / (8 * pthreads));
    std::vector<Top> tops;
    auto index = scratch<uint32_t>(n);  // each ref's bin indices, while its node is split
    std::vector<uint32_t> subtree_top;  // top node of each subtree
    tops.push_back(Top{root});
    for (std::vector<uint32_t> level{0}; !level.empty();) {
        std::vector<uint32_t> work, next;
        std::vector<Task> tasks;
        for (const uint32_t i : level) {
            const Task& t = tops[i].task;
            if (pthreads == 1 || t.end - t.begin < top_min) {
                tops[i].subtree = static_cast<int32_t>(subtree_top.size());
                subtree_top.push_back(i);
            } else {
                work.push_back(i);
                tasks.push_back(t);
            }
        }
        std::vector<char> is_split(work.size());
        std::vector<Task> lefts(work.size()), rights(work.size());
        if (!work.empty()) split_level(refs, index.get(), tasks, pthreads, is_split, lefts, rights);
        for (std::size_t j = 0; j < work.size(); ++j) {
            if (!is_split[j]) {
                tops[work[j]].leaf = true;
                continue;
            }
            const auto left = static_cast<uint32_t>(tops.size());
            tops[work[j]].left = static_cast<int32_t>(left);
            tops.push_back(Top{lefts[j]});
            tops.push_back(Top{rights[j]});
            next.push_back(left);
            next.push_back(left + 1);
        }
        level = std::move(next);
    }

    // The subtrees, largest first, each on whichever thread is free.
    std::vector<uint32_t> order(subtree_top.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
        const Task &ta = tops[subtree_top[a]].task, &tb = tops[subtree_top[b]].task;
        return ta.end - ta.begin > tb.end - tb.begin;
    });
    std::vector<std::vector<Node>> subtrees(subtree_top.size());
    run_jobs(pthreads, order.size(), [&](std::size_t j) {
        const Task& t = tops[subtree_top[order[j]]].task;
        std::vector<Node>& nodes = subtrees[order[j]];
        reserve_huge(nodes, 2 * std::size_t(t.end - t.begin) - 1);
        nodes.emplace_back();
        build_subtree(refs, index.get(), nodes, 0, t);
    });

    // Final layout: the order in which a sequential build allocates nodes (sibling pairs,
    // depth first). A subtree's root goes where its parent put it, the rest of it in one
    // block (local node i >= 1 at base + i - 1). Camera casts rely on this: every subtree
    // is one block (ProjectedScene::plan_subtrees).
    if (subtrees.size() == 1) {  // one thread: the subtree is the whole tree, laid out already
        scene.nodes = std::move(subtrees[0]);
    } else {
    std::size_t total = 0;
    for (const Top& top : tops)
        if (top.subtree < 0) ++total;
    for (const auto& s : subtrees) total += s.size();
    reserve_huge(scene.nodes, total);
    scene.nodes.resize(total);
    std::vector<std::pair<uint32_t, uint32_t>> placed(subtrees.size());  // (root position, base)
    uint32_t next = 1;
    std::vector<std::pair<uint32_t, uint32_t>> stack{{0u, 0u}};  // (top node, position)
    while (!stack.empty()) {
        const auto [i, pos] = stack.back();
        stack.pop_back();
        const Top& top = tops[i];
        if (top.subtree >= 0) {
            placed[top.subtree] = {pos, next};
            next += static_cast<uint32_t>(subtrees[top.subtree].size() - 1);
            continue;
        }
        Node& node = scene.nodes[pos];
        node.box = top.task.box.box();
        if (top.leaf) {
            node.index = top.task.begin;
            node.count = top.task.end - top.task.begin;
            continue;
        }
        node.index = next;
        node.count = 0;
        next += 2;
        stack.emplace_back(static_cast<uint32_t>(top.left + 1), node.index + 1);
        stack.emplace_back(static_cast<uint32_t>(top.left), node.index);
    }
    run_jobs(pthreads, order.size(), [&](std::size_t j) {
        const std::vector<Node>& local = subtrees[order[j]];
        const auto [pos, base] = placed[order[j]];
        for (std::size_t i = 0; i < local.size(); ++i) {
            Node node = local[i];
            if (!node.is_leaf()) node.index = base + node.index - 1;
            scene.nodes[i == 0 ? pos : base + i - 1] = node;
        }
        std::vector<Node>().swap(subtrees[order[j]]);
    });
    }
    scene.bounds = scene.nodes[0].box;

    reserve_huge(scene.prim_ids, n_triangles);
    reserve_huge(scene.triangles, 3 * n_triangles);
    scene.prim_ids.resize(n_triangles);
    scene.triangles.resize(3 * n_triangles);
    run_jobs(pthreads, chunks, [&](std::size_t t) {
        for (uint32_t i = slice(0, n, t, chunks), e = slice(0, n, t + 1, chunks); i < e; ++i) {
            const uint32_t id = refs[i].id;
            scene.prim_ids[i] = id;
            for (int c = 0; c < 3; ++c) scene.triangles[3 * std::size_t(i) + c] = triangles[3 * std::size_t(id) + c];
        }
    });
    order_points(scene, points, n_points);
    build_camera_tree(scene);
    build_wide(scene, pthreads);
    scene.binary_nodes = scene.nodes.size();
    std::vector<Node>().swap(scene.nodes);
    return scene;
}

}  // namespace vrc

#else  // no AVX2: the previous builder (binned SAH, three passes per node, scalar)

namespace vrc {
namespace {


constexpr int kBins = 16;
constexpr uint32_t kMaxLeaf = 8;             // forced split above this many triangles
constexpr float kTraversalCost = 4.0f;  // SAH cost of a node visit, in triangle tests (frog: 4 over 2, camera casts ~9 % fewer instructions, 24 % less memory; 8 as 4)
constexpr std::size_t kParallelGrain = 1u << 14;  // do not hand smaller subtrees to a new thread
constexpr int kMaxSahDepth = 64;  // below this, median splits: depth stays < 96 (traversal stack 128)

struct PrimRef {
    Box box;
    float centroid[3];
    uint32_t id;
};

struct Builder {
    std::vector<PrimRef>& refs;
    std::vector<Node>& nodes;
    std::atomic<uint32_t> next_node{1};
    std::atomic<int> spare_threads;

    Builder(std::vector<PrimRef>& r, std::vector<Node>& n, int threads) : refs(r), nodes(n), spare_threads(threads - 1) {}

    void build(uint32_t node_index, uint32_t begin, uint32_t end, int depth) {
        Node& node = nodes[node_index];
        Box centroids;
        node.box = Box{};
        for (uint32_t i = begin; i < end; ++i) {
            node.box.grow(refs[i].box);
            centroids.grow(refs[i].centroid);
        }
        const uint32_t count = end - begin;
        uint32_t mid = depth < kMaxSahDepth ? split(begin, end, centroids, node.box) : median(begin, end, centroids);
        if (mid == begin || mid == end) {
            if (count <= kMaxLeaf) {
                node.index = begin;
                node.count = count;
                return;
            }
            mid = median(begin, end, centroids);
        }
        const uint32_t left = next_node.fetch_add(2);
        node.index = left;
        node.count = 0;
        if (count >= kParallelGrain && spare_threads.fetch_sub(1) > 0) {
            std::thread helper([&] { build(left, begin, mid, depth + 1); });
            build(left + 1, mid, end, depth + 1);
            helper.join();
            spare_threads.fetch_add(1);
        } else {
            if (count >= kParallelGrain) spare_threads.fetch_add(1);
            build(left, begin, mid, depth + 1);
            build(left + 1, mid, end, depth + 1);
        }
    }

    /// Object median along the widest centroid axis: always splits in two halves.
    uint32_t median(uint32_t begin, uint32_t end, const Box& centroids) {
        int axis = 0;
        for (int k = 1; k < 3; ++k)
            if (centroids.hi[k] - centroids.lo[k] > centroids.hi[axis] - centroids.lo[axis]) axis = k;
        const uint32_t mid = begin + (end - begin) / 2;
        std::nth_element(refs.begin() + begin, refs.begin() + mid, refs.begin() + end, [axis](const PrimRef& a, const PrimRef& b) {
            return a.centroid[axis] < b.centroid[axis] || (a.centroid[axis] == b.centroid[axis] && a.id < b.id);
        });
        return mid;
    }

    /// Partitions refs[begin, end) at the cheapest binned SAH plane over all three axes.
    /// Returns begin (or end) when a leaf is cheaper than any split.
    uint32_t split(uint32_t begin, uint32_t end, const Box& centroids, const Box& bounds) {
        const uint32_t count = end - begin;
        if (count <= 1) return begin;
        // Fewer bins for small nodes: the per-node cost stays proportional to its size.
        const int n_bins = static_cast<int>(std::min<uint32_t>(kBins, std::max<uint32_t>(4, count)));
        Box bins[3][kBins];
        uint32_t counts[3][kBins] = {};
        float scale[3];
        for (int k = 0; k < 3; ++k) {
            const float extent = centroids.hi[k] - centroids.lo[k];
            const float s = extent > 0.0f ? n_bins / extent : 0.0f;
            scale[k] = std::isfinite(s) ? s : 0.0f;
        }
        auto bin_of = [&](const PrimRef& r, int k) {
            const int b = static_cast<int>((r.centroid[k] - centroids.lo[k]) * scale[k]);
            return std::min(std::max(b, 0), n_bins - 1);
        };
        for (uint32_t i = begin; i < end; ++i) {
            for (int k = 0; k < 3; ++k) {
                const int b = bin_of(refs[i], k);
                bins[k][b].grow(refs[i].box);
                ++counts[k][b];
            }
        }
        float best_cost = static_cast<float>(in_blocks(count));  // cost of a leaf
        int best_axis = -1, best_bin = 0;
        const float inv_area = 1.0f / std::max(bounds.half_area(), 1e-30f);
        for (int k = 0; k < 3; ++k) {
            if (scale[k] == 0.0f) continue;
            float right_area[kBins];
            uint32_t right_count[kBins];
            Box acc;
            uint32_t n = 0;
            for (int b = n_bins - 1; b > 0; --b) {
                acc.grow(bins[k][b]);
                n += counts[k][b];
                right_area[b] = acc.half_area();
                right_count[b] = n;
            }
            acc = Box{};
            n = 0;
            for (int b = 0; b < n_bins - 1; ++b) {
                acc.grow(bins[k][b]);
                n += counts[k][b];
                const float cost = kTraversalCost + (acc.half_area() * float(in_blocks(n)) +
                                                     right_area[b + 1] * float(in_blocks(right_count[b + 1]))) * inv_area;
                if (n > 0 && right_count[b + 1] > 0 && cost < best_cost) {
                    best_cost = cost;
                    best_axis = k;
                    best_bin = b;
                }
            }
        }
        if (best_axis < 0) return count > kMaxLeaf ? median(begin, end, centroids) : begin;
        auto first_right = std::partition(refs.begin() + begin, refs.begin() + end,
                                          [&](const PrimRef& r) { return bin_of(r, best_axis) <= best_bin; });
        return static_cast<uint32_t>(first_right - refs.begin());
    }
};

}  // namespace

Scene build_scene(const double* points, std::size_t n_points, const uint32_t* triangles, std::size_t n_triangles,
                  unsigned threads) {
    Scene scene;
    if (n_triangles == 0) return scene;

    frame_scene(scene, points, triangles, n_triangles);  // anchor, bounds and sphere

    std::vector<PrimRef> refs(n_triangles);
    for (std::size_t i = 0; i < n_triangles; ++i) {
        PrimRef& r = refs[i];
        for (int k = 0; k < 3; ++k) {
            double lo = points[3 * std::size_t(triangles[3 * i]) + k], hi = lo;
            for (int c = 1; c < 3; ++c) {
                const double x = points[3 * std::size_t(triangles[3 * i + c]) + k];
                lo = std::min(lo, x);
                hi = std::max(hi, x);
            }
            r.box.lo[k] = relative_down(lo, scene.anchor[k]);
            r.box.hi[k] = relative_up(hi, scene.anchor[k]);
            r.centroid[k] = 0.5f * (r.box.lo[k] + r.box.hi[k]);
        }
        r.id = static_cast<uint32_t>(i);
    }

    scene.nodes.resize(2 * n_triangles - 1);
    Builder builder(refs, scene.nodes, static_cast<int>(std::max(1u, threads)));
    builder.build(0, 0, static_cast<uint32_t>(n_triangles), 0);
    scene.nodes.resize(builder.next_node.load());
    shrink_huge(scene.nodes);

    scene.prim_ids.resize(n_triangles);
    scene.triangles.resize(3 * n_triangles);
    for (std::size_t i = 0; i < n_triangles; ++i) {
        const uint32_t id = refs[i].id;
        scene.prim_ids[i] = id;
        for (int c = 0; c < 3; ++c) scene.triangles[3 * i + c] = triangles[3 * std::size_t(id) + c];
    }
    order_points(scene, points, n_points);
    build_camera_tree(scene);
    build_wide(scene, std::max(1u, threads));
    scene.binary_nodes = scene.nodes.size();
    std::vector<Node>().swap(scene.nodes);
    return scene;
}

}  // namespace vrc

#endif
