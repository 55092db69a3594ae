// Every scene point projected into the image once per camera cast; a triangle's pixel
// rectangle from its three points.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// Pixels [c0, c1] x [r0, r1], inclusive, and a lower bound on the depth of what is
/// there to hit.
struct PixelRect {
    int64_t c0, c1, r0, r1;
    double near = -HUGE_VAL;
};

/// Each point's pixel column, row and depth for one camera, computed once per cast (the
/// workers share the points out) and read by every tile: a point serves about six
/// triangles, each met by several tiles or packets. Single precision, widened by its
/// rounding where used. A point with no usable projection (near or behind a pinhole's eye
/// plane) has a NaN column and row.
class ProjectedPoints {
    static constexpr double kEps = std::numeric_limits<double>::epsilon();

   public:
    ProjectedPoints(const Scene& scene, const CameraRays& rays)
        : scene_(scene), rays_(rays), map_(rays.pixel_map()), data_(new float[scene.points.size()]) {
        const CameraSpec& c = rays.spec();
        double depth_size = 0, parallel_size = std::fabs(map_.col0) + std::fabs(map_.row0);
        for (int k = 0; k < 3; ++k) {
            to_anchor_[k] = scene.anchor[k] - c.eye[k];
            // farthest reach of the scene's box from the anchor on this axis
            reach_[k] = std::max(std::fabs(double(scene.bounds.lo[k])), std::fabs(double(scene.bounds.hi[k])));
            if (!(reach_[k] < HUGE_VAL)) reach_[k] = 0;  // empty scene
            const double extent = std::fabs(to_anchor_[k]) + reach_[k];  // bounds |P - eye| on axis k
            depth_size += std::fabs(map_.depth[k]) * extent;
            parallel_size += std::max(std::fabs(map_.col[k]), std::fabs(map_.row[k])) * extent;
        }
        // (a parallel ray's origin leaves the eye plane by its own rounding)
        const double eye = std::max(std::fabs(c.eye[0]), std::max(std::fabs(c.eye[1]), std::fabs(c.eye[2])));
        depth_slack_ = 16 * kEps * (depth_size + (c.parallel ? eye + c.width + c.height : 0));
        // a parallel projection's rounding grows with |P - eye|
        margin_ = map_.margin + (c.parallel ? 16 * kEps * parallel_size : 0);
    }

    /// Projects worker `w`'s share of the points (of `workers`).
    void project(unsigned w, unsigned workers) {
        const std::size_t n = scene_.points.size() / 3, begin = n * w / workers, end = n * (w + 1) / workers;
        const CameraSpec& c = rays_.spec();
        for (std::size_t i = begin; i < end; ++i) {
            const double* p = scene_.point(uint32_t(i));
            const double q[3] = {p[0] - c.eye[0], p[1] - c.eye[1], p[2] - c.eye[2]};
            const double depth = dot(map_.depth, q);
            const double den = c.parallel ? 1.0 : depth;
            float* out = data_.get() + 3 * i;
            out[2] = float(depth);
            if (!c.parallel && !(den > CameraRays::PixelMap::kMinDen * (std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2])))) {
                out[0] = out[1] = std::numeric_limits<float>::quiet_NaN();
                continue;
            }
            out[0] = float((dot(map_.col, q) + map_.col0) / den);
            out[1] = float((dot(map_.row, q) + map_.row0) / den);
        }
    }

    enum class Reach { none, rect, unknown };
    /// Which pixels of the block [x0, x0 + w) x [y0, y0 + h) triangle `tri` may be hit
    /// through: none (its projection misses the block, or its depths all lie outside
    /// [near, far]), the pixels of `rect` (the block's own coordinates), or unknown (a point
    /// has no usable projection: every pixel).
    [[nodiscard]] Reach rect(const uint32_t tri[3], int64_t x0, int64_t y0, int64_t w, int64_t h, double near,
                             double far, PixelRect& out) const {
        const float *a = (*this)[tri[0]], *b = (*this)[tri[1]], *c = (*this)[tri[2]];
        const double lo_z = std::min(a[2], std::min(b[2], c[2])), hi_z = std::max(a[2], std::max(b[2], c[2]));
        out.near = lo_z - 0x1p-23 * std::fabs(lo_z) - depth_slack_;
        if (out.near > far || hi_z + 0x1p-23 * std::fabs(hi_z) + depth_slack_ < near) return Reach::none;
        if (!(a[0] == a[0] && b[0] == b[0] && c[0] == c[0])) return Reach::unknown;  // NaN: no projection
        const float lo_c = std::min(a[0], std::min(b[0], c[0])), hi_c = std::max(a[0], std::max(b[0], c[0]));
        const float lo_r = std::min(a[1], std::min(b[1], c[1])), hi_r = std::max(a[1], std::max(b[1], c[1]));
        // the projection's own margin, plus the rounding to single precision
        const double mc = margin_ + 0x1p-23 * double(std::max(-lo_c, hi_c));
        const double mr = margin_ + 0x1p-23 * double(std::max(-lo_r, hi_r));
        out.c0 = first_at_least(double(lo_c) - mc - double(x0), w);
        out.c1 = last_at_most(double(hi_c) + mc - double(x0), w);
        out.r0 = first_at_least(double(lo_r) - mr - double(y0), h);
        out.r1 = last_at_most(double(hi_r) + mr - double(y0), h);
        return out.c0 <= out.c1 && out.r0 <= out.r1 ? Reach::rect : Reach::none;
    }

    /// Column, row and depth of point i.
    [[nodiscard]] const float* operator[](uint32_t i) const { return data_.get() + 3 * std::size_t(i); }
    [[nodiscard]] const double* to_anchor() const { return to_anchor_; }  ///< anchor - eye
    [[nodiscard]] const double* reach() const { return reach_; }          ///< box extent from the anchor
    [[nodiscard]] double depth_slack() const { return depth_slack_; }     ///< rounding of any depth

   private:
    /// First integer >= x, clamped to [0, n]; last integer <= x, clamped to [-1, n - 1].
    /// (Clamping first keeps the conversions defined; x is never NaN here.)
    static int64_t first_at_least(double x, int64_t n) {
        x = std::min(std::max(x, -1.0), double(n));
        const int64_t i = int64_t(x);  // truncation: ceil for x <= 0, floor above
        return std::max<int64_t>(0, i + (double(i) < x));
    }
    static int64_t last_at_most(double x, int64_t n) {
        x = std::min(std::max(x, -1.0), double(n));
        const int64_t i = int64_t(x);
        return std::min<int64_t>(n - 1, i - (double(i) > x));
    }

    const Scene& scene_;
    const CameraRays& rays_;
    CameraRays::PixelMap map_;
    std::unique_ptr<float[]> data_;
    double to_anchor_[3], reach_[3], depth_slack_, margin_;
};

}  // namespace vrc
