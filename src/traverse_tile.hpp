// Coherent camera rays. Through a BVH, each tile's rays traverse as one packet from the
// tile's entry node: a node is culled once per packet against the packet's pixels (with
// the node's image rectangle, projected_scene.hpp) and against the depths its rays still
// search there, and a leaf's triangles are tested only on the pixels whose centres their
// projection can cover. On a flat scene (no BVH) a tile takes the pixels its triangles
// were rasterised into instead (bin_triangles.hpp). The ray-triangle test itself is the
// per-ray one (test_triangle), so every result equals the ray-by-ray traversal's; only the
// work of finding candidates is shared. Frustum and occlusion culling of a ray packet follow
// Reshetov, Soupikov and Hurley, "Multi-level ray tracing algorithm" (SIGGRAPH 2005), and
// Wald, Boulos and Shirley, "Ray tracing deformable scenes using dynamic bounding volume
// hierarchies" (ACM TOG 2007).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <new>
#include <optional>
#include <type_traits>
#include <vector>

#include "camera_rays.hpp"
#include "bin_triangles.hpp"
#include "kernel_watertight.hpp"
#include "kernel_watertight4.hpp"
#include "projected_scene.hpp"
#include "traverse.hpp"

namespace vrc {

/// Pixels [c0, c1] x [r0, r1] of a block, in its own coordinates (inclusive), and a lower
/// bound on the depth of what is there to hit.
struct PixelRect {
    int64_t c0, c1, r0, r1;
    double near = -HUGE_VAL;
    double far = HUGE_VAL;  ///< an upper bound on that depth (unknown: infinite)
};

template <template <class> class KernelT, class Real>
class TileTracer {
    using Kernel = KernelT<Real>;

   public:
    /// `by_triangle`: the cast asks only for what the hit triangle decides, not the hit's
    /// depth or weights (see test_pixel). `point_rows`: it interpolates the mesh's point
    /// arrays (see test_pixel).
    TileTracer(const Scene& scene, const CameraRays& rays, const ProjectedScene& projected, const CastContext& context,
               bool by_triangle, bool point_rows)
        : scene_(scene), rays_(rays), projected_(projected), context_(context), map_(rays.pixel_map()),
          sure_allowed_(kSureHits && std::is_same_v<Kernel, Watertight<double>>), by_triangle_(by_triangle),
          point_rows_(point_rows) {
        const int64_t n = kStride * kStride;
        ray_.resize(n);
        kernel_.resize(n);
        hit_.resize(n);
        bound_.resize(n);
        scale_.resize(n);
        depth_bound_.assign(n + 7, -HUGE_VAL);  // (test_pixels reads eight at a time)
        quad_.assign(n / 4, -HUGE_VAL);
        guess_far_.resize(n);
        guess_.resize(n);
        sure_.resize(n);
        sure_near_.resize(n + 7);  // (settle8 writes eight at a time)
    }

    /// Per-pixel arrays hold a whole tile (a packet, or a flat scene's block), row by row.
    static constexpr int64_t kStride = CameraRays::kTile, kQuads = kStride / 2;
    /// The point arrays' rows a row of hits interpolates are asked for this many rows before
    /// it is stored: a whole tile's at once outgrew the cache before the last were read.
    static constexpr int64_t kRowsAhead = 2;
    static_assert(kStride >= 2 && (kStride & (kStride - 1)) == 0, "test_pixels finds a pixel's quad with masks");
    static_assert(kStride <= 64, "a row's made rays are the bits of one word");

    /// Traces the tile's rays as one packet and writes each pixel's hit with `store`
    /// (store(pixel, ray, hit) for a ray made, store.settled(pixel, triangle) for a sure
    /// hit, store.misses(pixel, n) for a run of misses; first store.prefetch(triangle) for
    /// each hit of the tile, then store.prefetch_rows(triangles, n) for all of them).
    template <class Store>
    void trace(std::size_t tile, Store&& store) {
        const CameraRays::TilePixels t = rays_.tile_pixels(tile);
        const uint32_t entry = rays_.tile_may_hit(tile) && !scene_.camera.nodes.empty() ? entry_node(t) : kNoNode;
        if (entry == kNoNode) return misses(t, store);  // no node's rectangle meets the tile
        start(t);
        traverse(t, entry);
        finish(store);
    }

    /// A flat scene's tile (no BVH) that may see the scene: the pixels its triangles may
    /// cover (`bins`, see bin_triangles.hpp). Each pixel first tests its likely hit (the
    /// nearest triangle whose projection seems to cover its centre), whose depth then culls
    /// the rest.
    template <class Store>
    void trace_bin(std::size_t tile, const TriangleBins& bins, Store&& store) {
        const CameraRays::TilePixels p = rays_.tile_pixels(tile);
        bool any = false;
        for (unsigned w = 0; w < bins.workers(); ++w) any |= !bins.list(w, tile).empty();
        if (!any) return misses(p, store);
        start(p);
        std::fill(guess_far_.begin(), guess_far_.end(), HUGE_VALF);
        for (unsigned w = 0; w < bins.workers(); ++w)
            for (const TriangleBins::Entry& e : bins.list(w, tile)) {
                const int64_t j = e.c0 + e.r0 * kStride;  // (a rectangle's far is inf)
                if (e.far < guess_far_[j]) guess_far_[j] = e.far, guess_[j] = e.triangle;
            }
        for (int64_t j = 0; j < kStride * kStride; ++j)
            if (guess_far_[j] < HUGE_VALF) test_pixel(j % kStride, j / kStride, guess_[j]);
        for (unsigned w = 0; w < bins.workers(); ++w)
            for (const TriangleBins::Entry& e : bins.list(w, tile)) {
                if (!e.one_pixel()) {
                    test_pixels(e.triangle, {e.c0, e.c1, e.r0, e.r1, e.near});
                    continue;
                }
                const int64_t j = e.c0 + e.r0 * kStride;
                if (double(e.near) > depth_bound_[j] || (guess_far_[j] < HUGE_VALF && guess_[j] == e.triangle)) continue;
                test_pixel(e.c0, e.r0, e.triangle);
            }
        finish(store);
    }

   private:
    static constexpr uint32_t kNoNode = UINT32_MAX;

    /// Stores a miss for each pixel of a tile nothing in it can hit, without making rays.
    template <class Store>
    void misses(const CameraRays::TilePixels& p, Store& store) const {
        const int64_t nx = int64_t(rays_.spec().nx);
        for (int64_t r = p.r0; r <= p.r1; ++r) store.misses(std::size_t(p.i0 + r * nx), std::size_t(p.i1 - p.i0 + 1));
    }

    /// The tile's entry point (Reshetov et al. 2005): the deepest node whose subtree holds
    /// every node whose rectangle meets the tile, so its packets skip the levels above;
    /// kNoNode when none does.
    uint32_t entry_node(const CameraRays::TilePixels& t) {
        if (!overlaps(t, projected_.node(0).rect)) return kNoNode;
        uint32_t current = 0;
        while (projected_.node(current).count == 0) {
            const uint32_t left = projected_.node(current).index;
            const bool vl = overlaps(t, projected_.node(left).rect), vr = overlaps(t, projected_.node(left + 1).rect);
            if (vl == vr) return vl ? current : kNoNode;
            current = vl ? left : left + 1;
        }
        return current;
    }

    /// Empties the rays of the block p; they are made when first tested (most blocks of a
    /// sparse frame see no triangle).
    void start(const CameraRays::TilePixels& p) {
        i0_ = p.i0, r0_ = p.r0;
        width_ = p.i1 - p.i0 + 1;
        height_ = p.r1 - p.r0 + 1;
        // (an odd width or height leaves a column or row of quads half outside the block:
        // its outside slots hold -inf, so they never keep a node visible)
        for (int64_t r = 0; r < height_ + (height_ & 1); ++r)
            for (int64_t c = 0; c < width_ + (width_ & 1); ++c)
                depth_bound_[c + r * kStride] = c < width_ && r < height_ ? HUGE_VAL : -HUGE_VAL;
        std::fill(made_, made_ + kStride, 0);
        std::fill(sure_bits_, sure_bits_ + kStride, 0);
        for (int64_t r = 0; r < (height_ + 1) / 2; ++r)
            for (int64_t c = 0; c < (width_ + 1) / 2; ++c) quad_[c + r * kQuads] = HUGE_VAL;
    }

    /// Whether an image rectangle meets the pixels p.
    [[nodiscard]] static bool overlaps(const CameraRays::TilePixels& p, const ImageRect& q) {
        return q.c0 <= p.i1 && q.c1 >= p.i0 && q.r0 <= p.r1 && q.r1 >= p.r0;
    }

    /// Stores the block's rows: its hits (rays made, sure hits) and the runs of misses
    /// between them, each pixel written once.
    template <class Store>
    void finish(Store& store) {
        if (!by_triangle_) complete_sure_hits();
        uint64_t hits[kStride];
        std::size_t n_hits = 0, row_hits[kStride + 1];
        for (int64_t r = 0; r < height_; ++r) {
            row_hits[r] = n_hits;
            hits[r] = sure_bits_[r];
            for (uint64_t m = made_[r]; m != 0; m &= m - 1) {
                const int64_t j = __builtin_ctzll(m) + r * kStride;
                if (hit_[j].found()) hits[r] |= uint64_t(1) << (j % kStride), store.prefetch(hit_prims_[n_hits++] = hit_[j].prim);
            }
            for (uint64_t m = sure_bits_[r]; m != 0; m &= m - 1)
                store.prefetch(hit_prims_[n_hits++] = sure_[__builtin_ctzll(m) + r * kStride]);
        }
        row_hits[height_] = n_hits;
        const auto rows_of = [&](int64_t r) {
            if (r < height_) store.prefetch_rows(hit_prims_ + row_hits[r], row_hits[r + 1] - row_hits[r]);
        };
        for (int64_t r = 0; r < kRowsAhead; ++r) rows_of(r);
        for (int64_t r = 0; r < height_; ++r) {
            rows_of(r + kRowsAhead);
            for (int64_t c = 0; c < width_;) {
                const int64_t j = c + r * kStride;
                const uint64_t ahead = hits[r] >> c;
                if (!(ahead & 1)) {  // a run of misses up to the next hit (or the row's end)
                    const int64_t run = ahead ? std::min<int64_t>(__builtin_ctzll(ahead), width_ - c) : width_ - c;
                    store.misses(pixel(j), std::size_t(run));
                    c += run;
                    continue;
                }
                if (sure_bits_[r] >> c & 1)
                    store.settled(pixel(j), sure_[j]);
                else
                    store(pixel(j), ray_[j], hit_[j]);
                ++c;
            }
        }
    }

    /// Makes the pixels settled by sure hits hits of rays made, when the cast asks for their
    /// depth or weights: each pixel's ray is tested on its sure hit alone (the only triangle
    /// it can hit first, see test_pixel), four at a time in the lanes of watertight4, or with
    /// the scalar kernel for a lane it leaves. All of a tile's are tested before any is
    /// stored, so that the tests' long chains of divisions overlap one another (stores in
    /// between would each wait on theirs).
    void complete_sure_hits() {
#if defined(__AVX2__)
        int64_t lane_pixel[4], col[4], row[4];
        int n = 0;
        const auto flush = [&] {
            for (int l = n; l < 4; ++l) col[l] = col[0], row[l] = row[0], lane_pixel[l] = lane_pixel[0];
            Rays4 rays;
            int exponent[4];
            const unsigned made = rays_.rays4(col, row, rays, exponent);
            const double* corner[4][3];
            for (int l = 0; l < 4; ++l) {
                const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(sure_[lane_pixel[l]]);
                for (int c = 0; c < 3; ++c) corner[l][c] = scene_.point(tri[c]);
            }
            double t[4], b[4][3];
            const unsigned settled = made & watertight4(rays, corner, context_.cull_back_faces, t, b);
            for (int l = 0; l < n; ++l) {
                const int64_t j = lane_pixel[l];
                Hit<Real>& hit = hit_[j];
                Ray& ray = ray_[j];
                hit = Hit<Real>{};
                if (settled >> l & 1) {  // (a store reads only the ray's depth scale)
                    hit.t = t[l], hit.prim = sure_[j];
                    for (int c = 0; c < 3; ++c) hit.b[c] = b[l][c];
                    ray.t_unit = rays_.t_unit();
                    ray.t_exponent = exponent[l];
                } else {
                    rays_.set_ray(ray, col[l], row[l]);
                    double bound = ray.tmax;
                    test_triangle(Kernel(ray, context_), scene_, sure_[j], ray.tmin, bound, hit);
                }
            }
            n = 0;
        };
        for (int64_t r = 0; r < height_; ++r) {
            for (uint64_t m = sure_bits_[r]; m != 0; m &= m - 1) {
                const int64_t j = __builtin_ctzll(m) + r * kStride;
                col[n] = i0_ + j % kStride, row[n] = r0_ + j / kStride;
                lane_pixel[n++] = j;
                if (n == 4) flush();
            }
            made_[r] |= sure_bits_[r];
        }
        if (n != 0) flush();
        std::fill(sure_bits_, sure_bits_ + kStride, 0);
#endif
    }

    /// The image pixel of the block's ray j (column j % kStride, row j / kStride).
    [[nodiscard]] std::size_t pixel(int64_t j) const {
        return std::size_t((i0_ + j % kStride) + (r0_ + j / kStride) * int64_t(rays_.spec().nx));
    }

    /// Whether a node may hold a triangle some ray of the block reaches before its hit:
    /// its rectangle meets the block, and some 2x2 quad of pixels there still searches
    /// beyond the node's nearest depth (a hierarchical depth test, in the spirit of Greene,
    /// Kass and Miller, "Hierarchical Z-buffer visibility", SIGGRAPH 1993).
    [[nodiscard]] bool visible(const CameraRays::TilePixels& packet, const ImageRect& q) const {
        if (!overlaps(packet, q)) return false;
        const PixelRect p = local(packet, q);
        for (int64_t r = p.r0 >> 1; r <= p.r1 >> 1; ++r)
            for (int64_t c = p.c0 >> 1; c <= p.c1 >> 1; ++c)
                if (quad_[c + r * kQuads] >= p.near) return true;
        return false;
    }

    /// The tile's traversal from its entry node: visible children nearest first,
    /// a leaf's triangles on the pixels their rectangles cover. What a cast reads (the
    /// projected nodes and points, the triangles: tens of MB for a large scene) is mostly
    /// out of cache, so both children ask for what they read next as soon as they are
    /// loaded, before they are tested, and a leaf for its triangles' points
    /// (benchmarks/compare_builds.py, frog at 1024x1024: 10 % less time on one thread or
    /// two with prefetches once a child was chosen; 2.5 % less again on two threads, 4 %
    /// on one, with them issued before the tests).
    ///
    /// Leaves go through a pipeline of three: a leaf found asks for its triangles (every
    /// line of their points' indices), the one found before it for its points, and the one
    /// before that is tested, if the hits found since have not hidden it. Testing a leaf as
    /// soon as it was found had stalled on loading its triangles (46 % of the tile loop's
    /// samples): the frog at 1024x1024 takes 0.86x to 0.88x the time on two threads, 0.88x
    /// on one. The hits a leaf finds cull later than they would: a bumpy sphere filling the
    /// frame, whose 330 k triangles stay in cache, takes 1.02x (1.04x without the re-check).
    void traverse(const CameraRays::TilePixels& packet, uint32_t entry) {
        const ProjectedNode* stack[128];
        int top = 0;
        const ProjectedNode* node = &projected_.node(entry);
        if (!visible(packet, node->rect)) return;
        const ProjectedNode* leaves[2];  // queued: [0] its points asked for, [1] the last found
        int queued = 0;
        for (;;) {
            if (node->count != 0) {
                projected_.prefetch_triangles(*node);
                if (queued == 2) {
                    projected_.prefetch_points(leaves[1]->index, leaves[1]->count);
                    if (visible(packet, leaves[0]->rect)) test_leaf(packet, leaves[0]->index, leaves[0]->count);
                    leaves[0] = leaves[1];
                    leaves[1] = node;
                } else {
                    if (queued == 1) projected_.prefetch_points(leaves[0]->index, leaves[0]->count);
                    leaves[queued++] = node;
                }
            } else {
                const ProjectedNode* left = &projected_.node(node->index);
                projected_.prefetch(left[0]);  // (the tests' work overlaps the loads)
                projected_.prefetch(left[1]);
                const bool vl = visible(packet, left[0].rect), vr = visible(packet, left[1].rect);
                if (vl || vr) {
                    const ProjectedNode *first = left, *second = left + 1;
                    if (!vl || (vr && second->rect.near < first->rect.near)) std::swap(first, second);
                    if (vl && vr) stack[top++] = second;
                    node = first;
                    continue;
                }
            }
            do {  // pop, skipping nodes now hidden behind the hits found
                if (top == 0) {
                    if (queued == 2) projected_.prefetch_points(leaves[1]->index, leaves[1]->count);
                    for (int k = 0; k < queued; ++k)
                        if (visible(packet, leaves[k]->rect)) test_leaf(packet, leaves[k]->index, leaves[k]->count);
                    return;
                }
                node = stack[--top];
            } while (!visible(packet, node->rect));
        }
    }

    /// Tests the triangles first .. first + count - 1 (a leaf's) on the packet's pixels
    /// their rectangles cover.
    void test_leaf(const CameraRays::TilePixels& packet, uint32_t first, uint32_t count) {
#if defined(__AVX2__)
        // Eight triangles at a time: their rectangles, then those on at most four pixels of
        // the packet (nearly all of a framed frog's, two thirds of a terrain's filling the
        // frame) through Footprint's test there, all at once; the others go pixel by pixel
        // through test_pixels.
        const __m256 i0 = _mm256_set1_ps(float(packet.i0)), i1 = _mm256_set1_ps(float(packet.i1)),
                     r0 = _mm256_set1_ps(float(packet.r0)), r1 = _mm256_set1_ps(float(packet.r1));
        for (uint32_t i = first, end = first + count; i < end; i += 8) {
            const ProjectedScene::Rects8 q = projected_.triangles8(i, std::min(end - i, 8u));
            const __m256 meets = _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(q.c0, i1, _CMP_LE_OQ), _mm256_cmp_ps(q.c1, i0, _CMP_GE_OQ)),
                                               _mm256_and_ps(_mm256_cmp_ps(q.r0, r1, _CMP_LE_OQ), _mm256_cmp_ps(q.r1, r0, _CMP_GE_OQ)));
            unsigned lanes = unsigned(_mm256_movemask_ps(meets));
            if (lanes == 0) continue;
            // the part within the packet
            const __m256 c0 = _mm256_max_ps(q.c0, i0), c1 = _mm256_min_ps(q.c1, i1), rr0 = _mm256_max_ps(q.r0, r0),
                         rr1 = _mm256_min_ps(q.r1, r1);
            // On at most four pixels (one; two side by side or one above the other; a row or a
            // column of three or four; a square of four): Footprint's test on each, all at
            // once. Lane k's pixels: its rectangle's first and last corners, then the others.
            const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1);
            const __m256 wide = _mm256_sub_ps(c1, c0), tall = _mm256_sub_ps(rr1, rr0), spread = _mm256_add_ps(wide, tall);
            const __m256 line = _mm256_cmp_ps(_mm256_min_ps(wide, tall), zero, _CMP_EQ_OQ);
            const __m256 square = _mm256_andnot_ps(line, _mm256_cmp_ps(spread, _mm256_set1_ps(2), _CMP_EQ_OQ));
            const __m256 line4 = _mm256_and_ps(line, _mm256_cmp_ps(spread, _mm256_set1_ps(3), _CMP_EQ_OQ));
            const unsigned single = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(spread, zero, _CMP_EQ_OQ)));
            const unsigned pair = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(spread, one, _CMP_EQ_OQ)));
            const unsigned four = unsigned(_mm256_movemask_ps(_mm256_or_ps(square, line4)));
            const unsigned more = four | (unsigned(_mm256_movemask_ps(_mm256_and_ps(line, _mm256_cmp_ps(spread, _mm256_set1_ps(2), _CMP_EQ_OQ)))));
            const unsigned small = single | pair | more;
            __m256 cols[4] = {c0, c1}, rows[4] = {rr0, rr1};
            unsigned may[4] = {}, sure[4] = {};
            const auto cover = [&](auto pixels) {
                constexpr int kPixels = decltype(pixels)::value;
                const auto c = projected_.cover8<kPixels>(q, cols, rows, !context_.cull_back_faces);
                for (int p = 0; p < kPixels; ++p)
                    may[p] = unsigned(_mm256_movemask_ps(c.may[p])), sure[p] = unsigned(_mm256_movemask_ps(c.sure[p]));
            };
            alignas(32) int32_t at[4][2][8];  // pixel p of each lane (column, row), in the block's coordinates
            const __m256 to_c = _mm256_set1_ps(float(i0_)), to_r = _mm256_set1_ps(float(r0_));
            const auto place = [&](int p) {
                _mm256_store_si256(reinterpret_cast<__m256i*>(at[p][0]), _mm256_cvtps_epi32(_mm256_sub_ps(cols[p], to_c)));
                _mm256_store_si256(reinterpret_cast<__m256i*>(at[p][1]), _mm256_cvtps_epi32(_mm256_sub_ps(rows[p], to_r)));
            };
            if (lanes & more) {  // a square's other two corners; a line's inner pixels
                const __m256 step_c = _mm256_min_ps(wide, one), step_r = _mm256_min_ps(tall, one);
                cols[2] = _mm256_blendv_ps(_mm256_add_ps(c0, step_c), c1, square);
                rows[2] = _mm256_blendv_ps(_mm256_add_ps(rr0, step_r), rr0, square);
                cols[3] = _mm256_blendv_ps(_mm256_add_ps(c0, _mm256_add_ps(step_c, step_c)), c0, square);
                rows[3] = _mm256_blendv_ps(_mm256_add_ps(rr0, _mm256_add_ps(step_r, step_r)), rr1, square);
                cover(std::integral_constant<int, 4>{});
                place(2), place(3);
            } else {
                cover(std::integral_constant<int, 2>{});
            }
            place(0), place(1);
            alignas(32) float near[8], far[8];
            _mm256_store_ps(near, q.near);
            _mm256_store_ps(far, q.far);
            // (lanes whose footprint misses their pixels are dropped here, not branched on)
            const unsigned on[4] = {lanes & small & may[0], lanes & (pair | more) & may[1], lanes & more & may[2],
                                    lanes & four & may[3]};
            for (lanes = (lanes & ~small) | on[0] | on[1] | on[2] | on[3]; lanes != 0; lanes &= lanes - 1) {
                const int k = __builtin_ctz(lanes);
                const uint32_t triangle = i + uint32_t(k);
                if (!(small >> k & 1)) {
                    test_pixels(triangle, {at[0][0][k], at[1][0][k], at[0][1][k], at[1][1][k], near[k], far[k]});
                    continue;
                }
                bool fetched = false;
                const auto test = [&](int p) {
                    const int64_t c = at[p][0][k], r = at[p][1][k];
                    if (double(near[k]) > depth_bound_[c + r * kStride]) return;
                    if (!fetched) scene_.prefetch_points(triangle), fetched = true;  // (for the kernel)
                    try_pixel(c, r, triangle, near[k], far[k], sure[p] >> k & 1);
                };
                if (on[0] >> k & 1) test(0);
                if (on[1] >> k & 1) test(1);
                if (more >> k & 1) {
                    if (on[2] >> k & 1) test(2);
                    if (on[3] >> k & 1) test(3);
                }
            }
        }
#else
        for (uint32_t i = first, end = first + count; i < end; ++i) {
            const ImageRect q = projected_.triangle(i);
            if (overlaps(packet, q)) test_pixels(i, local(packet, q));
        }
#endif
    }

    /// The part within pixels p of an image rectangle that meets them, in the block's
    /// coordinates.
    [[nodiscard]] PixelRect local(const CameraRays::TilePixels& p, const ImageRect& q) const {
        return {std::max<int64_t>(q.c0, p.i0) - i0_, std::min<int64_t>(q.c1, p.i1) - i0_, std::max<int64_t>(q.r0, p.r0) - r0_,
                std::min<int64_t>(q.r1, p.r1) - r0_, q.near};
    }

    /// Tests triangle i on the block's pixels in `rect`.
    void test_pixels(uint32_t i, const PixelRect& rect) {
        std::optional<Footprint> footprint;  // set up once a pixel needs it (a quarter of the frog's never do)
#if defined(__AVX2__)
        // Eight pixels of a row at a time: the depth and footprint tests of each give bits,
        // and only the pixels that pass both branch (a pixel's test changes only its own
        // depth bound, so the later ones' bits stay right).
        const __m256d near = _mm256_set1_pd(rect.near);
        const bool sure_depths = projected_.sure_depths(float(rect.near), float(rect.far)), either_side = !context_.cull_back_faces;
        for (int64_t r = rect.r0; r <= rect.r1; ++r)
            for (int64_t c = rect.c0; c <= rect.c1; c += 8) {
                const double* bound = depth_bound_.data() + c + r * kStride;  // (padded: may read 7 past the end)
                const unsigned beyond = unsigned(_mm256_movemask_pd(_mm256_cmp_pd(near, _mm256_loadu_pd(bound), _CMP_GT_OQ))) |
                                        unsigned(_mm256_movemask_pd(_mm256_cmp_pd(near, _mm256_loadu_pd(bound + 4), _CMP_GT_OQ))) << 4;
                unsigned open = ~beyond & (0xffu >> std::max<int64_t>(0, c + 7 - rect.c1));
                if (!open) continue;
                if (!footprint) footprint.emplace(projected_.footprint(i));
                const auto [may, sure] = footprint->may_cover8(i0_ + c, r0_ + r, either_side);
                open &= may;
                if (sure_allowed_ && sure_depths && open != 0 && (open & ~sure) == 0 &&
                    !((made_[r] | sure_bits_[r]) >> c & open)) {
                    settle8(c, r, i, open, float(rect.near), float(rect.far));
                    continue;
                }
                for (; open != 0; open &= open - 1) {
                    const int b = __builtin_ctz(open);
                    try_pixel(c + b, r, i, float(rect.near), float(rect.far), sure_depths && (sure >> b & 1));
                }
            }
#else
        for (int64_t r = rect.r0; r <= rect.r1; ++r)
            for (int64_t c = rect.c0; c <= rect.c1; ++c) {
                const int64_t j = c + r * kStride;
                if (rect.near > depth_bound_[j]) continue;  // beyond this ray's hit
                if (!footprint) {
                    scene_.prefetch_points(i);  // for the kernel, while the footprint is set up
                    footprint.emplace(projected_.footprint(i));
                }
                if (footprint->may_cover(i0_ + c, r0_ + r)) try_pixel(c, r, i, float(rect.near), float(rect.far), false);
            }
#endif
    }

#if defined(__AVX2__)
    /// Settles the pixels `open` (bits) of columns c to c + 7 of row r by sure hits of
    /// triangle i, whose depths lie within [near, far], when none of them has a ray or a
    /// sure hit yet: what try_pixel does to each (test_pixel's first sure hit, then the
    /// quads' depth bounds), in vector lanes. A large triangle's pixels mostly go so.
    void settle8(int64_t c, int64_t r, uint32_t i, unsigned open, float near, float far) {
        const int64_t j = c + r * kStride;
        sure_bits_[r] |= uint64_t(open) << c;
        const __m256i bits32 = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        const __m256i in32 = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(open)), bits32), bits32);
        _mm256_maskstore_epi32(reinterpret_cast<int*>(sure_.data() + j), in32, _mm256_set1_epi32(int(i)));
        _mm256_maskstore_ps(sure_near_.data() + j, in32, _mm256_set1_ps(near));
        const __m256i bits64 = _mm256_setr_epi64x(1, 2, 4, 8);
        const __m256d bound = _mm256_set1_pd(double(far));
        for (int half = 0; half < 2; ++half) {
            const __m256i in64 = _mm256_cmpeq_epi64(_mm256_and_si256(_mm256_set1_epi64x(open >> 4 * half), bits64), bits64);
            _mm256_maskstore_pd(depth_bound_.data() + j + 4 * half, in64, bound);
        }
        ask_point_rows(i);
        const int64_t last = c + 31 - __builtin_clz(open);
        for (int64_t qc = (c + __builtin_ctz(open)) >> 1; qc <= last >> 1; ++qc) bound_quad(qc, r >> 1);
    }
#endif

    /// Tests triangle i, whose depths lie within [near, far], on the block's ray at column
    /// c, row r (`sure`: surely hit, see test_pixel); on a closer hit, the depth bounds of
    /// the ray and of its quad follow.
    void try_pixel(int64_t c, int64_t r, uint32_t i, float near, float far, bool sure) {
        if (test_pixel(c, r, i, near, far, sure)) bound_quad(c >> 1, r >> 1);
    }

    /// The depth bound of the 2x2 quad of pixels at quad column qc, row qr: its pixels' largest.
    void bound_quad(int64_t qc, int64_t qr) {
        const int64_t q = 2 * qc + 2 * qr * kStride;  // the quad's first pixel
        quad_[qc + qr * kQuads] = std::max(std::max(depth_bound_[q], depth_bound_[q + 1]),
                                           std::max(depth_bound_[q + kStride], depth_bound_[q + kStride + 1]));
    }

    /// With the mesh's point arrays interpolated, asks the cache for what finds the rows of
    /// a sure hit's corners when stored (its points' input indices).
    void ask_point_rows(uint32_t i) const {
        if (!point_rows_) return;
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(i);
        for (int k = 0; k < 3; ++k) prefetch_line(scene_.point_ids.data() + tri[k]);
    }

    /// Tests triangle i on the block's ray at column c, row r; on a closer hit, the ray's
    /// depth bound follows and this returns true.
    ///
    /// A sure hit settles a pixel's triangle without its ray (with the watertight kernel in
    /// double): the pixel's first candidate, when the kernel surely hits it (`sure`, from
    /// the footprint tests that found the pixel; ProjectedScene::SureHits), is recorded
    /// with its depth bounds, and no ray is made. A later candidate is culled when its
    /// nearest depth lies beyond the sure hit's farthest: each bound clears the exact depths
    /// by the depth slack plus 2^-21 relative, far beyond the kernel's rounding of t and its
    /// tie tolerance, so the kernel would rank it behind. By the same margins a later
    /// candidate surely hit whose farthest depth lies before the sure hit's nearest takes
    /// its place (a leaf's triangles come in no order of depth, so such candidates are
    /// common where surfaces overlap). Any
    /// other candidate makes the ray, and the kernel tests the sure hit, then it: the
    /// kernel decides every close call.
    /// When the cast asks for the hit's depth or weights, the rays of the pixels still
    /// settled so are made once the tile is traversed, and tested on their sure hit alone
    /// (complete_sure_hits).
    bool test_pixel(int64_t c, int64_t r, uint32_t i, float near = -HUGE_VALF, float far = HUGE_VALF, bool sure = false) {
        const int64_t j = c + r * kStride;
        const uint64_t bit = uint64_t(1) << c;
        bool resolved = false;  // a sure hit was just tested with the kernel
        if (!(made_[r] & bit)) {
#if defined(__AVX2__)
            if (sure_allowed_ && sure && (!(sure_bits_[r] & bit) || far < sure_near_[j])) {
                sure_bits_[r] |= bit;
                sure_[j] = i;
                sure_near_[j] = near;
                depth_bound_[j] = double(far);
                ask_point_rows(i);
                return true;
            }
#endif
            make_ray(j);
            if (sure_bits_[r] & bit) {
                sure_bits_[r] &= ~bit;
                test_triangle(kernel(j), scene_, sure_[j], ray_[j].tmin, bound_[j], hit_[j]);
                resolved = true;
            }
        }
        const double before = bound_[j];
        test_triangle(kernel(j), scene_, i, ray_[j].tmin, bound_[j], hit_[j]);
        if (bound_[j] == before && !resolved) return false;
        depth_bound_[j] = bound_[j] * scale_[j] * (1 + 1e-12) + projected_.depth_slack();  // rounded up
        return true;
    }

    void make_ray(int64_t j) {
        made_[j / kStride] |= uint64_t(1) << (j % kStride);
        rays_.set_ray(ray_[j], i0_ + j % kStride, r0_ + j / kStride);
        new (kernel_[j].bytes) Kernel(ray_[j], context_);
        hit_[j] = Hit<Real>{};
        bound_[j] = ray_[j].tmax;  // t; depth_bound_ stays unbounded until a hit
        scale_[j] = dot(map_.depth, ray_[j].dir);  // depth per unit of t
    }

    const Scene& scene_;
    const CameraRays& rays_;
    const ProjectedScene& projected_;
    CastContext context_;
    CameraRays::PixelMap map_;
    int64_t i0_ = 0, r0_ = 0, width_ = 0, height_ = 0;  // the block: a tile
    uint64_t made_[kStride];  // per row of the block, a bit for each pixel whose ray is made
    uint64_t sure_bits_[kStride];  // per row, a bit for each pixel settled by a sure hit (not made)
    bool sure_allowed_;            // see test_pixel
    bool by_triangle_;             // whether the cast asks only for what the hit triangle decides
    bool point_rows_;              // whether it interpolates the mesh's point arrays
#if defined(__AVX2__)
    static constexpr bool kSureHits = true;
#else
    static constexpr bool kSureHits = false;  // (they come with the AVX2 leaf loop, which knows triangles' depths)
#endif
    std::vector<uint32_t> sure_;   // the sure hit of each such pixel
    std::vector<float> sure_near_;  // and a lower bound on its depth there
    uint32_t hit_prims_[kStride * kStride];  // the block's hit triangles, for finish's prefetches
    std::vector<Ray> ray_;                       // ray_, kernel_ and hit_: set for the rays made only
    /// Room for a ray's kernel (which has no default state), made over whatever was there:
    /// a kernel is trivially destructible, and an optional's check of its old state was a
    /// load of a line about to be written, mostly a miss that held up the pixel's test.
    struct KernelRoom {
        alignas(Kernel) unsigned char bytes[sizeof(Kernel)];
    };
    static_assert(std::is_trivially_destructible_v<Kernel>, "a kernel is made over the last one");
    std::vector<KernelRoom> kernel_;
    Kernel& kernel(int64_t j) { return *std::launder(reinterpret_cast<Kernel*>(kernel_[j].bytes)); }
    std::vector<Hit<Real>> hit_;
    std::vector<double> bound_, scale_, depth_bound_;  // t of the hit, depth per unit t, depth of the hit rounded up
    std::vector<float> guess_far_;  // a flat scene's likely hit per pixel: its farthest point depth
    std::vector<uint32_t> guess_;
    std::vector<double> quad_;  // the largest depth_bound_ of each 2x2 quad of pixels
};

}  // namespace vrc
