// Camera casts on a flat scene (no BVH, as a one-shot cast builds none): each triangle is
// binned to the tiles its projected pixel rectangle touches, by a counting sort that keeps
// the input order within a tile.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "projected_scene.hpp"

namespace vrc {

class TriangleBins {
   public:
    /// A triangle in a tile's list, with the pixels of the tile it may cover.
    struct Entry {
        double near;  ///< lower bound on its depth
        uint32_t triangle;
        uint8_t c0, c1, r0, r1;  ///< pixel rectangle in the tile's own coordinates
    };

    TriangleBins(const Scene& scene, const CameraRays& rays, const ProjectedScene& projected, unsigned workers)
        : scene_(scene), rays_(rays), projected_(projected), workers_(workers), n_tiles_(rays.n_tiles()),
          tiles_x_((rays.spec().nx + CameraRays::kTile - 1) / CameraRays::kTile),
          counts_(std::size_t(workers) * n_tiles_, 0), rects_(new ImageRect[scene.n_triangles()]), unknown_(workers) {}

    /// First pass, by worker w: the pixel rectangles of its share of the triangles, and
    /// their count per tile.
    void count(unsigned w) {
        uint32_t* counts = counts_.data() + std::size_t(w) * n_tiles_;
        unknown_[w].clear();
        for (std::size_t i = share(w), end = share(w + 1); i < end; ++i) {
            ImageRect& rect = rects_[i];
            if (projected_.frame_triangle(scene_.triangles.data() + 3 * i, rect) == ProjectedScene::Reach::unknown) {
                unknown_[w].push_back(uint32_t(i));
                rect = kNoPixels;  // binned nowhere
            }
            for_each_tile(rect, [&](int64_t, int64_t, std::size_t tile) { ++counts[tile]; });
        }
    }

    /// Second pass, by worker w once every worker counted: places its triangles.
    void place(unsigned w) {
        if (w == 0) {  // offsets: tile by tile, and within a tile worker by worker (input order)
            std::size_t total = 0;
            offsets_.assign(n_tiles_ + 1, 0);
            for (std::size_t t = 0; t < n_tiles_; ++t) {
                offsets_[t] = total;
                for (unsigned v = 0; v < workers_; ++v) total += counts_[std::size_t(v) * n_tiles_ + t];
            }
            offsets_[n_tiles_] = total;
            list_.reset(new Entry[total]);
            ready_.store(true);
        }
        while (!ready_.load()) std::this_thread::yield();
        std::vector<std::size_t> next(n_tiles_);
        for (std::size_t t = 0; t < n_tiles_; ++t) {
            next[t] = offsets_[t];
            for (unsigned v = 0; v < w; ++v) next[t] += counts_[std::size_t(v) * n_tiles_ + t];
        }
        constexpr int64_t k = CameraRays::kTile;
        const auto local = [](int64_t v, int64_t origin) { return uint8_t(std::min(std::max(v - origin, int64_t(0)), k - 1)); };
        for (std::size_t i = share(w), end = share(w + 1); i < end; ++i) {
            const ImageRect& r = rects_[i];
            for_each_tile(r, [&](int64_t tx, int64_t ty, std::size_t tile) {
                list_[next[tile]++] = {double(r.near), uint32_t(i), local(r.c0, tx * k), local(r.c1, tx * k),
                                       local(r.r0, ty * k), local(r.r1, ty * k)};
            });
        }
    }

    [[nodiscard]] const Entry* begin(std::size_t tile) const { return list_.get() + offsets_[tile]; }
    [[nodiscard]] const Entry* end(std::size_t tile) const { return list_.get() + offsets_[tile + 1]; }
    /// Triangles with no usable projection (crossing a pinhole's eye plane), in input order.
    [[nodiscard]] std::vector<uint32_t> unknown() const {
        std::vector<uint32_t> all;
        for (const auto& u : unknown_) all.insert(all.end(), u.begin(), u.end());
        return all;
    }

   private:
    /// First triangle of worker w's share.
    [[nodiscard]] std::size_t share(unsigned w) const { return scene_.n_triangles() * w / workers_; }

    /// Calls f(tile column, tile row, tile) for each tile the rectangle touches.
    template <class F>
    void for_each_tile(const ImageRect& r, F&& f) const {
        if (r.empty()) return;
        for (int64_t ty = r.r0 / CameraRays::kTile; ty <= r.r1 / CameraRays::kTile; ++ty)
            for (int64_t tx = r.c0 / CameraRays::kTile; tx <= r.c1 / CameraRays::kTile; ++tx)
                f(tx, ty, std::size_t(tx + ty * tiles_x_));
    }

    const Scene& scene_;
    const CameraRays& rays_;
    const ProjectedScene& projected_;
    unsigned workers_;
    std::size_t n_tiles_;
    int64_t tiles_x_;
    std::vector<uint32_t> counts_;  // (worker, tile)
    std::vector<std::size_t> offsets_;
    std::unique_ptr<ImageRect[]> rects_;  // each triangle's (empty when binned nowhere)
    std::unique_ptr<Entry[]> list_;
    std::vector<std::vector<uint32_t>> unknown_;  // per worker
    std::atomic<bool> ready_{false};
};

}  // namespace vrc
