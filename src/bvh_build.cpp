// Binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding volume
// hierarchies"). The passes per node are kept to two (binning, partition): the node's box
// and its centroids' box come from the parent (the union of the parent's bins on each side
// of the plane, and bounds accumulated while partitioning). With several threads the top
// nodes are binned and partitioned by all threads together (each bins a slice, the bins are
// merged; each partitions a slice, misplaced blocks are swapped), then the subtrees below
// are built by whichever thread is free, each into its own node array in depth-first
// order. The arrays are stitched at the end in the order a sequential build allocates
// nodes, so the tree (and its layout) does not depend on thread timing, and a one-thread
// build is the sequential builder's tree exactly.
#include <algorithm>
#include <array>
#include <atomic>
#include <cstdlib>
#include <memory>
#include <cmath>
#include <cstring>
#include <thread>

#include <immintrin.h>

#include "bvh.hpp"

namespace vrc {
namespace {

constexpr int kBins = 16;
constexpr uint32_t kMaxLeaf = 8;        // forced split above this many triangles
constexpr float kTraversalCost = 2.0f;  // SAH cost of a node visit, in triangle tests (frog: 2 builds ~15 % faster than 1, 20 % less memory)
constexpr uint32_t kMinTopNode = 1u << 15;  // smallest node binned/partitioned by all threads together
constexpr int kMaxSahDepth = 64;  // below this, median splits: depth stays < 96 (traversal stack 128)

/// A triangle's box (relative to the anchor, rounded outward) and its input index; 32 bytes,
/// two aligned SIMD loads. Its centroid is computed on the fly: 0.5 * (lo + hi).
struct alignas(32) Ref {
    float lo[3];
    uint32_t id;
    float hi[3];
    float pad;
};
static_assert(sizeof(Ref) == 32, "refs are meant to be 32 bytes");

inline __m128 load_lo(const Ref& r) {  // lane 3 (the id's bits) zeroed: no denormal operands
    return _mm_blend_ps(_mm_load_ps(r.lo), _mm_setzero_ps(), 8);
}
inline __m128 load_hi(const Ref& r) { return _mm_load_ps(r.hi); }
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
    [[nodiscard]] float half_area() const { return box().half_area(); }
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
    __m128 clo, scale;
    __m128i last;
    int n_bins;
    float scale_k[3];
    Binner(const VBox& cbox, uint32_t count) {
        n_bins = static_cast<int>(std::min<uint32_t>(kBins, std::max<uint32_t>(4, count)));
        const Box c = cbox.box();
        for (int k = 0; k < 3; ++k) {
            const float extent = c.hi[k] - c.lo[k];
            const float s = extent > 0.0f ? n_bins / extent : 0.0f;
            scale_k[k] = std::isfinite(s) ? s : 0.0f;
        }
        clo = cbox.lo;
        scale = _mm_setr_ps(scale_k[0], scale_k[1], scale_k[2], 0.0f);
        last = _mm_set1_epi32(n_bins - 1);
    }
    [[nodiscard]] __m128i bin(__m128 c) const {
        const __m128i b = _mm_cvttps_epi32(_mm_mul_ps(_mm_sub_ps(c, clo), scale));
        return _mm_min_epi32(_mm_max_epi32(b, _mm_setzero_si128()), last);
    }
};

struct Bins {
    VBox box[3][kBins];
    uint32_t count[3][kBins] = {};

    void add(const Ref* refs, uint32_t begin, uint32_t end, const Binner& binner) {
        for (uint32_t i = begin; i < end; ++i) {
            const __m128 lo = load_lo(refs[i]), hi = load_hi(refs[i]);
            const __m128i b = binner.bin(centroid(lo, hi));
            const int b0 = _mm_extract_epi32(b, 0), b1 = _mm_extract_epi32(b, 1), b2 = _mm_extract_epi32(b, 2);
            box[0][b0].grow(lo, hi);
            box[1][b1].grow(lo, hi);
            box[2][b2].grow(lo, hi);
            ++count[0][b0];
            ++count[1][b1];
            ++count[2][b2];
        }
    }
    void merge(const Bins& o, int n_bins) {
        for (int k = 0; k < 3; ++k)
            for (int b = 0; b < n_bins; ++b) {
                box[k][b].grow(o.box[k][b]);
                count[k][b] += o.count[k][b];
            }
    }
};

struct Split {
    int axis = -1, bin = 0;
    uint32_t n_left = 0;
    VBox left, right;
};

/// The cheapest binned SAH plane over all three axes; axis -1 when a leaf is cheaper.
Split best_split(const Bins& bins, const Binner& binner, uint32_t count, const VBox& bounds) {
    const int n_bins = binner.n_bins;
    Split best;
    float best_cost = static_cast<float>(count);  // cost of a leaf
    const float inv_area = 1.0f / std::max(bounds.half_area(), 1e-30f);
    for (int k = 0; k < 3; ++k) {
        if (binner.scale_k[k] == 0.0f) continue;
        float right_area[kBins];
        uint32_t right_count[kBins];
        VBox acc;
        uint32_t n = 0;
        for (int b = n_bins - 1; b > 0; --b) {
            acc.grow(bins.box[k][b]);
            n += bins.count[k][b];
            right_area[b] = acc.half_area();
            right_count[b] = n;
        }
        acc = VBox{};
        n = 0;
        for (int b = 0; b < n_bins - 1; ++b) {
            acc.grow(bins.box[k][b]);
            n += bins.count[k][b];
            const float cost = kTraversalCost + (acc.half_area() * n + right_area[b + 1] * right_count[b + 1]) * inv_area;
            if (n > 0 && right_count[b + 1] > 0 && cost < best_cost) {
                best_cost = cost;
                best.axis = k;
                best.bin = b;
            }
        }
    }
    if (best.axis >= 0) {
        for (int b = 0; b < n_bins; ++b) {
            if (b <= best.bin) {
                best.left.grow(bins.box[best.axis][b]);
                best.n_left += bins.count[best.axis][b];
            } else {
                best.right.grow(bins.box[best.axis][b]);
            }
        }
    }
    return best;
}

/// Partitions refs[begin, end) into those whose centroid bin on `axis` is <= `bin` and the
/// rest (the same swaps as libstdc++'s std::partition), and the boxes of both sides'
/// centroids. Every element is classified exactly once.
uint32_t partition(Ref* refs, uint32_t begin, uint32_t end, const Binner& binner, int axis, int bin, VBox& cleft,
                   VBox& cright) {
    auto is_left = [&](const Ref& r) {
        const __m128 c = centroid(load_lo(r), load_hi(r));
        alignas(16) int32_t b[4];
        _mm_store_si128(reinterpret_cast<__m128i*>(b), binner.bin(c));
        if (b[axis] <= bin) {
            cleft.grow(c);
            return true;
        }
        cright.grow(c);
        return false;
    };
    uint32_t first = begin, last = end;
    while (true) {
        while (true) {
            if (first == last) return first;
            if (is_left(refs[first]))
                ++first;
            else
                break;
        }
        --last;
        while (true) {
            if (first == last) return first;
            if (!is_left(refs[last]))
                --last;
            else
                break;
        }
        std::swap(refs[first], refs[last]);
        ++first;
    }
}

void bounds_of(const Ref* refs, uint32_t begin, uint32_t end, VBox& box, VBox& cbox) {
    for (uint32_t i = begin; i < end; ++i) {
        const __m128 lo = load_lo(refs[i]), hi = load_hi(refs[i]);
        box.grow(lo, hi);
        cbox.grow(centroid(lo, hi));
    }
}

/// Object median along the widest centroid axis: always splits in two halves.
uint32_t median(Ref* refs, const Task& t) {
    const Box c = t.cbox.box();
    int axis = 0;
    for (int k = 1; k < 3; ++k)
        if (c.hi[k] - c.lo[k] > c.hi[axis] - c.lo[axis]) axis = k;
    const uint32_t mid = t.begin + (t.end - t.begin) / 2;
    std::nth_element(refs + t.begin, refs + mid, refs + t.end, [axis](const Ref& a, const Ref& b) {
        return 0.5f * (a.lo[axis] + a.hi[axis]) < 0.5f * (b.lo[axis] + b.hi[axis]);
    });
    return mid;
}

/// Runs f(0) .. f(n - 1), f(0) on the calling thread.
template <class F>
void run_parallel(unsigned n, F&& f) {
    if (n <= 1) {
        f(0u);
        return;
    }
    std::vector<std::thread> helpers;
    helpers.reserve(n - 1);
    for (unsigned t = 1; t < n; ++t) helpers.emplace_back([&f, t] { f(t); });
    f(0u);
    for (auto& h : helpers) h.join();
}

inline uint32_t slice(uint32_t begin, uint32_t end, unsigned t, unsigned n) {
    return begin + static_cast<uint32_t>((uint64_t(end - begin) * t) / n);
}

/// The split of one node, decided (and the triangles partitioned) by one thread or by all.
/// Returns false for a leaf; otherwise fills the two children's tasks.
bool split_node(Ref* refs, const Task& t, unsigned threads, Task& left, Task& right) {
    const uint32_t count = t.end - t.begin;
    uint32_t mid = t.begin;
    bool split = false;
    if (t.depth >= kMaxSahDepth) {
        mid = median(refs, t);  // down to single triangles, as the sequential builder
    } else if (count > 1) {
        const Binner binner(t.cbox, count);
        Bins bins;
        if (threads <= 1) {
            bins.add(refs, t.begin, t.end, binner);
        } else {
            std::vector<Bins> part(threads);
            run_parallel(threads, [&](unsigned i) {
                part[i].add(refs, slice(t.begin, t.end, i, threads), slice(t.begin, t.end, i + 1, threads), binner);
            });
            bins = part[0];
            for (unsigned i = 1; i < threads; ++i) bins.merge(part[i], binner.n_bins);
        }
        const Split s = best_split(bins, binner, count, t.box);
        if (s.axis >= 0) {
            left.cbox = right.cbox = VBox{};
            if (threads <= 1) {
                mid = partition(refs, t.begin, t.end, binner, s.axis, s.bin, left.cbox, right.cbox);
            } else {
                mid = t.begin + s.n_left;
                struct Part {
                    uint32_t begin, mid, end;
                    VBox cl, cr;
                };
                std::vector<Part> part(threads);
                run_parallel(threads, [&](unsigned i) {
                    Part& p = part[i];
                    p.begin = slice(t.begin, t.end, i, threads);
                    p.end = slice(t.begin, t.end, i + 1, threads);
                    p.mid = partition(refs, p.begin, p.end, binner, s.axis, s.bin, p.cl, p.cr);
                });
                // Right-side runs that lie left of `mid` and left-side runs right of it: as
                // many of each; swap them pairwise, in parallel slices.
                std::vector<std::pair<uint32_t, uint32_t>> wrong_r, wrong_l;
                for (const Part& p : part) {
                    left.cbox.grow(p.cl);
                    right.cbox.grow(p.cr);
                    if (p.mid < mid) wrong_r.emplace_back(p.mid, std::min(p.end, mid));
                    if (p.mid > mid) wrong_l.emplace_back(std::max(p.begin, mid), p.mid);
                }
                uint64_t n_wrong = 0;
                for (auto& r : wrong_r) n_wrong += r.second - r.first;
                auto locate = [](const std::vector<std::pair<uint32_t, uint32_t>>& runs, uint64_t k, std::size_t& run,
                                 uint32_t& pos) {
                    run = 0;
                    while (k >= runs[run].second - runs[run].first) {
                        k -= runs[run].second - runs[run].first;
                        ++run;
                    }
                    pos = runs[run].first + static_cast<uint32_t>(k);
                };
                if (n_wrong > 0)
                    run_parallel(threads, [&](unsigned i) {
                        const uint64_t k0 = n_wrong * i / threads, k1 = n_wrong * (i + 1) / threads;
                        if (k0 == k1) return;
                        std::size_t ra, rb;
                        uint32_t a, b;
                        locate(wrong_r, k0, ra, a);
                        locate(wrong_l, k0, rb, b);
                        for (uint64_t k = k0; k < k1;) {
                            if (a == wrong_r[ra].second) a = wrong_r[++ra].first;
                            if (b == wrong_l[rb].second) b = wrong_l[++rb].first;
                            const uint32_t n = static_cast<uint32_t>(
                                std::min<uint64_t>({k1 - k, wrong_r[ra].second - a, wrong_l[rb].second - b}));
                            std::swap_ranges(refs + a, refs + a + n, refs + b);
                            a += n;
                            b += n;
                            k += n;
                        }
                    });
            }
            left.box = s.left;
            right.box = s.right;
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

/// Builds a subtree sequentially into `nodes` (its root at nodes[at]), allocating sibling
/// pairs in depth-first order.
void build_subtree(Ref* refs, std::vector<Node>& nodes, uint32_t at, const Task& t) {
    Task left, right;
    nodes[at].box = t.box.box();
    if (!split_node(refs, t, 1, left, right)) {
        nodes[at].index = t.begin;
        nodes[at].count = t.end - t.begin;
        return;
    }
    const auto pair = static_cast<uint32_t>(nodes.size());
    nodes[at].index = pair;
    nodes[at].count = 0;
    nodes.emplace_back();
    nodes.emplace_back();
    build_subtree(refs, nodes, pair, left);
    build_subtree(refs, nodes, pair + 1, right);
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
    scene.points.assign(points, points + 3 * n_points);
    if (n_triangles == 0) return scene;
    const uint32_t n = static_cast<uint32_t>(n_triangles);
    // Fewer threads for small meshes: a thread start costs about as much as ~10^4 triangles.
    const unsigned pthreads = static_cast<unsigned>(std::min<std::size_t>(n_threads, 1 + n_triangles / 16384));

    // The anchor: the centre of the triangles' bounding box, in double.
    std::vector<std::array<double, 6>> part_bounds(pthreads);
    run_parallel(pthreads, [&](unsigned t) {
        double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL}, hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
        const std::size_t e = 3 * std::size_t(slice(0, n, t + 1, pthreads));
        for (std::size_t i = 3 * std::size_t(slice(0, n, t, pthreads)); i < e; ++i) {
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
    std::vector<PointBox> pbox(n_points);
    std::vector<double> pdist(n_points);
    run_parallel(pthreads, [&](unsigned t) {
        const auto np = static_cast<uint32_t>(n_points);
        for (uint32_t i = slice(0, np, t, pthreads), e = slice(0, np, t + 1, pthreads); i < e; ++i) {
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
    auto* refs = static_cast<Ref*>(std::aligned_alloc(alignof(Ref), sizeof(Ref) * n_triangles));
    std::unique_ptr<Ref, void (*)(void*)> refs_owner(refs, std::free);
    std::vector<Task> part_root(pthreads);
    std::vector<double> part_r2(pthreads, 0.0);
    run_parallel(pthreads, [&](unsigned t) {
        VBox box, cbox;
        double r2 = 0;
        for (uint32_t i = slice(0, n, t, pthreads), e = slice(0, n, t + 1, pthreads); i < e; ++i) {
            const uint32_t* tri = triangles + 3 * std::size_t(i);
            __m128 lo = _mm_loadu_ps(pbox[tri[0]].lo), hi = _mm_loadu_ps(pbox[tri[0]].hi);
            for (int c = 1; c < 3; ++c) {
                lo = _mm_min_ps(_mm_loadu_ps(pbox[tri[c]].lo), lo);
                hi = _mm_max_ps(_mm_loadu_ps(pbox[tri[c]].hi), hi);
                r2 = std::max(r2, pdist[tri[c]]);
            }
            r2 = std::max(r2, pdist[tri[0]]);
            Ref& r = refs[i];
            _mm_store_ps(r.lo, lo);
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
    for (unsigned t = 0; t < pthreads; ++t) {
        root.box.grow(part_root[t].box);
        root.cbox.grow(part_root[t].cbox);
        r2 = std::max(r2, part_r2[t]);
    }
    scene.sphere_radius = std::sqrt(r2);
    pbox = {};
    pdist = {};

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
    std::vector<uint32_t> subtree_top;  // top node of each subtree
    tops.push_back(Top{root});
    for (std::size_t i = 0; i < tops.size(); ++i) {
        const Task t = tops[i].task;
        if (pthreads == 1 || t.end - t.begin < top_min) {
            tops[i].subtree = static_cast<int32_t>(subtree_top.size());
            subtree_top.push_back(static_cast<uint32_t>(i));
            continue;
        }
        Task left, right;
        if (!split_node(refs, t, pthreads, left, right)) {
            tops[i].leaf = true;
            continue;
        }
        tops[i].left = static_cast<int32_t>(tops.size());
        tops.push_back(Top{left});
        tops.push_back(Top{right});
    }

    // The subtrees, largest first, each on whichever thread is free.
    std::vector<uint32_t> order(subtree_top.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
        const Task &ta = tops[subtree_top[a]].task, &tb = tops[subtree_top[b]].task;
        return ta.end - ta.begin > tb.end - tb.begin;
    });
    std::vector<std::vector<Node>> subtrees(subtree_top.size());
    std::atomic<std::size_t> next_subtree{0};
    run_parallel(std::min<std::size_t>(pthreads, subtree_top.size()), [&](unsigned) {
        for (std::size_t j; (j = next_subtree.fetch_add(1)) < order.size();) {
            const Task& t = tops[subtree_top[order[j]]].task;
            std::vector<Node>& nodes = subtrees[order[j]];
            nodes.reserve(2 * std::size_t(t.end - t.begin) - 1);
            nodes.emplace_back();
            build_subtree(refs, nodes, 0, t);
        }
    });

    // Final layout: the order in which a sequential build allocates nodes (sibling pairs,
    // depth first). A subtree's root goes where its parent put it, the rest of it in one
    // block (local node i >= 1 at base + i - 1).
    std::size_t total = 0;
    for (const Top& top : tops)
        if (top.subtree < 0) ++total;
    for (const auto& s : subtrees) total += s.size();
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
    std::atomic<std::size_t> next_copy{0};
    run_parallel(std::min<std::size_t>(pthreads, subtrees.size()), [&](unsigned) {
        for (std::size_t j; (j = next_copy.fetch_add(1)) < order.size();) {
            const std::vector<Node>& local = subtrees[order[j]];
            const auto [pos, base] = placed[order[j]];
            for (std::size_t i = 0; i < local.size(); ++i) {
                Node node = local[i];
                if (!node.is_leaf()) node.index = base + node.index - 1;
                scene.nodes[i == 0 ? pos : base + i - 1] = node;
            }
            std::vector<Node>().swap(subtrees[order[j]]);
        }
    });
    scene.bounds = scene.nodes[0].box;

    scene.prim_ids.resize(n_triangles);
    scene.triangles.resize(3 * n_triangles);
    run_parallel(pthreads, [&](unsigned t) {
        for (uint32_t i = slice(0, n, t, pthreads), e = slice(0, n, t + 1, pthreads); i < e; ++i) {
            const uint32_t id = refs[i].id;
            scene.prim_ids[i] = id;
            for (int c = 0; c < 3; ++c) scene.triangles[3 * std::size_t(i) + c] = triangles[3 * std::size_t(id) + c];
        }
    });
    return scene;
}

}  // namespace vrc
