// Camera casts on a flat scene (no BVH, as a one-shot cast builds none), rasterised once
// per camera: each triangle over a few pixels adds an entry for each pixel whose ray it may
// hit (Footprint's test, in single precision) to that pixel's tile; a larger one adds its
// pixel rectangle to each tile it meets. Entries keep the input order within a worker's
// share of the triangles. The tracer then tests each pixel's likely hit first (the entry
// nearest in depth whose projection seems to cover the pixel's centre), so the entries
// behind it are culled by their nearest depth without a test.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>
#if defined(__SSE4_1__)
#include <immintrin.h>
#endif

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "projected_scene.hpp"

namespace vrc {

class TriangleBins {
   public:
    /// A pixel (or a rectangle of pixels) a triangle may cover, in its tile's list.
    struct Entry {
        float near;         ///< lower bound on the triangle's depth
        float far;          ///< its largest point depth when it seems to cover the pixel's centre, else inf
        uint32_t triangle;
        uint8_t c0, c1, r0, r1;  ///< its pixels in the tile: one, or a rectangle (see bin)
        [[nodiscard]] bool one_pixel() const { return c0 == c1 && r0 == r1; }
    };

    TriangleBins(const Scene& scene, const CameraRays& rays, const ProjectedScene& projected, unsigned workers)
        : scene_(scene), projected_(projected), workers_(workers), n_tiles_(rays.n_tiles()),
          tiles_x_((rays.spec().nx + CameraRays::kTile - 1) / CameraRays::kTile),
          lists_(std::size_t(workers) * n_tiles_) {}

    /// Worker w's share of the triangles, each into the tiles of the pixels it may cover.
    void bin(unsigned w) {
        std::vector<Entry>* lists = lists_.data() + std::size_t(w) * n_tiles_;
        for (std::size_t i = share(w), end = share(w + 1); i < end; ++i) {
            const uint32_t* tri = scene_.triangles.data() + 3 * i;
#if defined(__SSE4_1__)
            const __m128 pa = _mm_load_ps(projected_[tri[0]]), pb = _mm_load_ps(projected_[tri[1]]),
                         pc = _mm_load_ps(projected_[tri[2]]);
            const __m128 lo = _mm_min_ps(_mm_min_ps(pa, pb), pc), hi = _mm_max_ps(_mm_max_ps(pa, pb), pc);
            if (_mm_cvtss_f32(_mm_shuffle_ps(hi, hi, 3)) != 0) {  // a point with no usable projection
                add_cone(lists, uint32_t(i), tri);
                continue;
            }
            const __m128 span = projected_.pixel_span(lo, hi);  // (c0, c1, r0, r1)
            // most triangles of a fine mesh cover no pixel centre: c0 > c1 or r0 > r1
            if (_mm_movemask_ps(_mm_cmpgt_ps(span, _mm_shuffle_ps(span, span, _MM_SHUFFLE(2, 3, 0, 1)))) & 0b0101) continue;
            const float near = projected_.near_bound(_mm_cvtss_f32(_mm_movehl_ps(lo, lo)), _mm_cvtss_f32(_mm_movehl_ps(hi, hi)));
            if (near == HUGE_VALF) continue;
            alignas(16) int32_t p[4];
            _mm_store_si128(reinterpret_cast<__m128i*>(p), _mm_cvtps_epi32(span));
            rasterise(uint32_t(i), pa, pb, pc, lo, hi, near, p[0], p[1], p[2], p[3], lists);
#else
            ImageRect rect;
            const ProjectedScene::Reach reach = projected_.frame_triangle(tri, rect);
            if (reach == ProjectedScene::Reach::unknown) add_cone(lists, uint32_t(i), tri);
            if (reach != ProjectedScene::Reach::rect) continue;
            const Footprint footprint = projected_.footprint(uint32_t(i));
            for (int64_t r = rect.r0; r <= rect.r1; ++r)
                for (int64_t col = rect.c0; col <= rect.c1; ++col)
                    if (footprint.may_cover(col, r)) add(lists, col, r, {rect.near, HUGE_VALF, uint32_t(i), 0, 0, 0, 0});
#endif
        }
    }

    /// Worker w's entries for a tile.
    [[nodiscard]] const std::vector<Entry>& list(unsigned w, std::size_t tile) const {
        return lists_[std::size_t(w) * n_tiles_ + tile];
    }
    [[nodiscard]] unsigned workers() const { return workers_; }
   private:
    static constexpr int64_t kTile = CameraRays::kTile;
    /// Triangles over more pixels than this are binned as a rectangle per tile, tested
    /// pixel by pixel by the tracer: in single-pixel entries they cost more than their
    /// footprint test saves (compare_builds.py --flat, alternated: 2 pixels took 1.11x the
    /// time of 4 on the frog, 8 took 1.06x on the bumpy sphere).
    static constexpr int64_t kMaxPixels = 4;

    static_assert((kTile & (kTile - 1)) == 0, "tiles are found with shifts and masks");
    static constexpr int kShift = __builtin_ctzll(uint64_t(kTile));
    /// Adds entry e for image pixel (col, r) to its tile's list.
    void add(std::vector<Entry>* lists, int64_t col, int64_t r, Entry e) const {
        e.c0 = e.c1 = uint8_t(col & (kTile - 1));
        e.r0 = e.r1 = uint8_t(r & (kTile - 1));
        lists[(col >> kShift) + (r >> kShift) * tiles_x_].push_back(e);
    }
    /// Adds triangle i's pixels c0..c1 x r0..r1 to each tile they meet, as rectangles.
    void add_rect(std::vector<Entry>* lists, uint32_t i, float near, int64_t c0, int64_t c1, int64_t r0, int64_t r1) const {
        const auto local = [](int64_t v, int64_t origin) { return uint8_t(std::min(std::max(v - origin, int64_t(0)), kTile - 1)); };
        for (int64_t ty = r0 >> kShift; ty <= r1 >> kShift; ++ty)
            for (int64_t tx = c0 >> kShift; tx <= c1 >> kShift; ++tx)
                lists[tx + ty * tiles_x_].push_back({near, HUGE_VALF, i, local(c0, tx * kTile), local(c1, tx * kTile),
                                                     local(r0, ty * kTile), local(r1, ty * kTile)});
    }

    /// Triangle i, whose points `tri` include one with no usable projection (near or behind
    /// a pinhole's eye plane), on its rectangle (ProjectedScene::cone_rect), if any.
    void add_cone(std::vector<Entry>* lists, uint32_t i, const uint32_t tri[3]) const {
        ImageRect rect;
        if (projected_.frame_triangle(tri, rect) != ProjectedScene::Reach::none)
            add_rect(lists, i, rect.near, rect.c0, rect.c1, rect.r0, rect.r1);
    }

#if defined(__SSE4_1__)
    /// Triangle i (projected points pa, pb, pc within [lo, hi]) on the pixels c0..c1 x
    /// r0..r1: those whose rays it may hit, by its Footprint in single precision.
    void rasterise(uint32_t i, __m128 pa, __m128 pb, __m128 pc, __m128 lo, __m128 hi, float near, int64_t c0, int64_t c1,
                   int64_t r0, int64_t r1, std::vector<Entry>* lists) const {
        if ((c1 - c0 + 1) * (r1 - r0 + 1) > kMaxPixels) return add_rect(lists, i, near, c0, c1, r0, r1);
        const Footprint footprint(pa, pb, pc, lo, hi, projected_.margin(), projected_.sure_margin());
        const float far = _mm_cvtss_f32(_mm_movehl_ps(hi, hi));
        const auto test = [&](int64_t col, int64_t r, __m128 row) {
            const Footprint::Cover cover = footprint.cover(col, row);
            if (cover != Footprint::kNone) add(lists, col, r, {near, cover == Footprint::kInside ? far : HUGE_VALF, i, 0, 0, 0, 0});
        };
        if (c0 == c1 && r0 == r1) return test(c0, r0, footprint.row(r0));  // the usual case
        for (int64_t r = r0; r <= r1; ++r) {
            const __m128 row = footprint.row(r);
            for (int64_t col = c0; col <= c1; ++col) test(col, r, row);
        }
    }
#endif

    /// First triangle of worker w's share.
    [[nodiscard]] std::size_t share(unsigned w) const { return scene_.n_triangles() * w / workers_; }

    const Scene& scene_;
    const ProjectedScene& projected_;
    unsigned workers_;
    std::size_t n_tiles_;
    int64_t tiles_x_;
    std::vector<std::vector<Entry>> lists_;  // (worker, tile)
};

}  // namespace vrc
