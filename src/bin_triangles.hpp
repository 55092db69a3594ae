// Camera casts on a flat scene (no BVH, as a one-shot cast builds none): each triangle is
// binned to the tiles its projected pixel rectangle touches, by a counting sort that keeps
// the input order within a tile.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <thread>
#include <vector>

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "projected_points.hpp"

namespace vrc {

class TriangleBins {
   public:
    /// A triangle in a tile's list, with the pixels of the tile it may cover.
    struct Entry {
        double near;  ///< lower bound on its depth
        uint32_t triangle;
        uint8_t c0, c1, r0, r1;  ///< pixel rectangle in the tile's own coordinates
    };

    TriangleBins(const Scene& scene, const CameraRays& rays, const ProjectedPoints& projected, unsigned workers)
        : scene_(scene), rays_(rays), projected_(projected), workers_(workers), n_tiles_(rays.n_tiles()),
          tiles_x_((rays.spec().nx + CameraRays::kTile - 1) / CameraRays::kTile),
          counts_(std::size_t(workers) * n_tiles_, 0), unknown_(workers) {}

    /// First pass, by worker w: counts its share of the triangles per tile.
    void count(unsigned w) {
        uint32_t* counts = counts_.data() + std::size_t(w) * n_tiles_;
        for_each(w, [&](uint32_t, const PixelRect&, int64_t, int64_t, std::size_t tile) { ++counts[tile]; });
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
            list_.resize(total);
            ready_.store(true);
        }
        while (!ready_.load()) std::this_thread::yield();
        std::vector<std::size_t> next(n_tiles_);
        for (std::size_t t = 0; t < n_tiles_; ++t) {
            next[t] = offsets_[t];
            for (unsigned v = 0; v < w; ++v) next[t] += counts_[std::size_t(v) * n_tiles_ + t];
        }
        unknown_[w].clear();
        const int64_t k = CameraRays::kTile;
        for_each(
            w,
            [&](uint32_t i, const PixelRect& r, int64_t tx, int64_t ty, std::size_t tile) {
                const auto local = [&](int64_t v, int64_t origin) { return uint8_t(std::min(std::max(v - origin, int64_t(0)), k - 1)); };
                list_[next[tile]++] = {r.near, i, local(r.c0, tx * k), local(r.c1, tx * k), local(r.r0, ty * k), local(r.r1, ty * k)};
            },
            &unknown_[w]);
    }

    [[nodiscard]] const Entry* begin(std::size_t tile) const { return list_.data() + offsets_[tile]; }
    [[nodiscard]] const Entry* end(std::size_t tile) const { return list_.data() + offsets_[tile + 1]; }
    /// Triangles with no usable projection (crossing a pinhole's eye plane), in input order.
    [[nodiscard]] std::vector<uint32_t> unknown() const {
        std::vector<uint32_t> all;
        for (const auto& u : unknown_) all.insert(all.end(), u.begin(), u.end());
        return all;
    }

   private:
    /// Calls f(i, pixel rectangle, tile column, tile row, tile) for each tile worker w's
    /// triangles reach; those with no usable projection go to `unknown` instead.
    template <class F>
    void for_each(unsigned w, F&& f, std::vector<uint32_t>* unknown = nullptr) const {
        const std::size_t n = scene_.n_triangles(), begin = n * w / workers_, end = n * (w + 1) / workers_;
        const CameraSpec& c = rays_.spec();
        for (std::size_t i = begin; i < end; ++i) {
            PixelRect r;
            const auto reach = projected_.rect(scene_.triangles.data() + 3 * i, 0, 0, c.nx, c.ny, c.near, c.far, r);
            if (reach == ProjectedPoints::Reach::unknown && unknown) unknown->push_back(uint32_t(i));
            if (reach != ProjectedPoints::Reach::rect) continue;
            for (int64_t ty = r.r0 / CameraRays::kTile; ty <= r.r1 / CameraRays::kTile; ++ty)
                for (int64_t tx = r.c0 / CameraRays::kTile; tx <= r.c1 / CameraRays::kTile; ++tx)
                    f(uint32_t(i), r, tx, ty, std::size_t(tx + ty * tiles_x_));
        }
    }

    const Scene& scene_;
    const CameraRays& rays_;
    const ProjectedPoints& projected_;
    unsigned workers_;
    std::size_t n_tiles_;
    int64_t tiles_x_;
    std::vector<uint32_t> counts_;  // (worker, tile)
    std::vector<std::size_t> offsets_;
    std::vector<Entry> list_;
    std::vector<std::vector<uint32_t>> unknown_;  // per worker
    std::atomic<bool> ready_{false};
};

}  // namespace vrc
