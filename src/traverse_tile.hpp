// Coherent camera rays: a tile of pixels traverses the BVH together. Nodes are culled once
// per tile against the tile's frustum and against the farthest depth its rays still search;
// a leaf's triangles are projected into the tile and each is tested only on the pixels
// whose centres its projection can cover. The ray-triangle test itself is the per-ray one
// (test_triangle), so every result equals the ray-by-ray traversal's; only the work of
// finding candidates is shared. Frustum and occlusion culling of a ray packet follow
// Reshetov, Soupikov and Hurley, "Multi-level ray tracing algorithm" (SIGGRAPH 2005), and
// Wald, Boulos and Shirley, "Ray tracing deformable scenes using dynamic bounding volume
// hierarchies" (ACM TOG 2007).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "camera_rays.hpp"
#include "traverse.hpp"

namespace vrc {

/// Four doubles (GCC/Clang vector extension: AVX where the CPU has it, SSE2 otherwise):
/// the tile's four side planes evaluated at once.
using Double4 = double __attribute__((vector_size(32)));
using Mask4 = int64_t __attribute__((vector_size(32)));

/// Every scene point's pixel column, row and depth for one camera, computed once per cast
/// (shared among the workers) and shared by the tiles: a point serves about six triangles, each
/// visited by several packets. Single precision (the tracer widens its rectangles by the
/// rounding). A point with no usable projection (near or behind
/// a pinhole's eye plane) has a NaN column and row.
class ProjectedPoints {
   public:
    ProjectedPoints(const Scene& scene, const CameraRays& rays)
        : scene_(scene), rays_(rays), map_(rays.pixel_map()), data_(new float[scene.points.size()]) {}

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
            out[2] = float(depth);  // within 2^-24 relative: widened where used
            if (!c.parallel && !(den > CameraRays::PixelMap::kMinDen * (std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2])))) {
                out[0] = out[1] = std::numeric_limits<float>::quiet_NaN();
                continue;
            }
            out[0] = float((dot(map_.col, q) + map_.col0) / den);
            out[1] = float((dot(map_.row, q) + map_.row0) / den);
        }
    }
    /// Column, row and depth of point i.
    [[nodiscard]] const float* operator[](uint32_t i) const { return data_.get() + 3 * std::size_t(i); }

   private:
    const Scene& scene_;
    const CameraRays& rays_;
    CameraRays::PixelMap map_;
    std::unique_ptr<float[]> data_;
};

template <template <class> class KernelT, class Real>
class TileTracer {
    using Kernel = KernelT<Real>;
    static constexpr double kEps = std::numeric_limits<double>::epsilon();

    /// a.q + c >= -slack for every point q = P - eye a ray of the tile can reach, where
    /// c folds in the plane's constant and a.(anchor - eye); P - eye = (anchor - eye) + rel
    /// for a box corner rel (boxes are stored relative to the scene's anchor).
    struct Plane {
        double a[3], c, slack;
        /// Largest a.rel over the box.
        [[nodiscard]] double max_over(const Box& box) const {
            double s = 0;
            for (int k = 0; k < 3; ++k) s += a[k] * double(a[k] >= 0 ? box.hi[k] : box.lo[k]);
            return s;
        }
        /// Smallest a.rel over the box.
        [[nodiscard]] double min_over(const Box& box) const {
            double s = 0;
            for (int k = 0; k < 3; ++k) s += a[k] * double(a[k] >= 0 ? box.lo[k] : box.hi[k]);
            return s;
        }
    };

   public:
    TileTracer(const Scene& scene, const CameraRays& rays, const ProjectedPoints& projected, const CastContext& context)
        : scene_(scene), rays_(rays), projected_(projected), context_(context), map_(rays.pixel_map()) {
        const CameraSpec& c = rays.spec();
        const int64_t n = kPacket * kPacket;
        ray_.resize(n);
        kernel_.resize(n);
        hit_.resize(n);
        bound_.resize(n);
        scale_.resize(n);
        for (int k = 0; k < 3; ++k) {
            to_anchor_[k] = scene.anchor[k] - c.eye[k];
            // farthest reach of a stored box from the anchor on this axis
            reach_[k] = std::max(std::fabs(double(scene.bounds.lo[k])), std::fabs(double(scene.bounds.hi[k])));
            if (!(reach_[k] < HUGE_VAL)) reach_[k] = 0;  // empty scene
        }
        rect_margin_ = map_.margin;
        if (c.parallel) {  // a parallel projection's rounding grows with |P - eye|
            double size = std::fabs(map_.col0) + std::fabs(map_.row0);
            for (int k = 0; k < 3; ++k)
                size += std::max(std::fabs(map_.col[k]), std::fabs(map_.row[k])) * (std::fabs(to_anchor_[k]) + reach_[k]);
            rect_margin_ += 16 * kEps * size;
        }
        depth_ = plane(map_.depth, 0);
    }

    /// Rays go through the BVH in square packets of kPacket x kPacket pixels: small enough
    /// that a packet's rays usually all hit and end close in depth (what occlusion culling
    /// needs), large enough to share the node tests.
    static constexpr int64_t kPacket = 4;

    /// Traces the tile's rays, packet by packet, and calls store(pixel, ray, hit) for each.
    template <class Store>
    void trace(std::size_t tile, Store&& store) {
        const CameraRays::TilePixels t = rays_.tile_pixels(tile);
        const bool may_hit = rays_.tile_may_hit(tile) && !scene_.nodes.empty();
        for (int64_t r = t.r0; r <= t.r1; r += kPacket)
            for (int64_t i = t.i0; i <= t.i1; i += kPacket)
                trace({i, std::min(i + kPacket - 1, t.i1), r, std::min(r + kPacket - 1, t.r1)}, may_hit, store);
    }

   private:
    template <class Store>
    void trace(const CameraRays::TilePixels& p, bool may_hit, Store& store) {
        i0_ = p.i0;
        r0_ = p.r0;
        width_ = p.i1 - p.i0 + 1;
        height_ = p.r1 - p.r0 + 1;
        const int64_t n = width_ * height_, nx = int64_t(rays_.spec().nx);
        // Rays are made when first tested: most packets of a sparse frame see no triangle.
        for (int64_t j = 0; j < n; ++j) {
            kernel_[j].reset();
            hit_[j] = Hit<Real>{};
            bound_[j] = rays_.spec().far;  // a depth until the ray exists, then its t
            scale_[j] = 1;
        }
        if (may_hit) traverse(p);
        for (int64_t j = 0; j < n; ++j)
            store(std::size_t((i0_ + j % width_) + (r0_ + j / width_) * nx), ray_[j], hit_[j]);  // ray_ used on hits only
    }

    /// Half-space a.q + b >= 0 of q = P - eye, with its rounding slack over the scene.
    [[nodiscard]] Plane plane(const double a[3], double b) const {
        Plane h;
        double size = std::fabs(b);
        h.c = b;
        for (int k = 0; k < 3; ++k) {
            h.a[k] = a[k];
            h.c += a[k] * to_anchor_[k];
            size += std::fabs(a[k]) * (std::fabs(to_anchor_[k]) + reach_[k]);
        }
        h.slack = 16 * kEps * size;
        return h;
    }

    /// Column (or row) >= lo, written as a half-space of q: form.q + form0 - lo (den.q + den0).
    [[nodiscard]] Plane at_least(const double form[3], double form0, double lo) const {
        double a[3];
        for (int k = 0; k < 3; ++k) a[k] = form[k] - lo * map_.den[k];
        return plane(a, form0 - lo * map_.den0);
    }
    [[nodiscard]] Plane at_most(const double form[3], double form0, double hi) const {
        double a[3];
        for (int k = 0; k < 3; ++k) a[k] = hi * map_.den[k] - form[k];
        return plane(a, hi * map_.den0 - form0);
    }

    /// Whether the box may hold a point some ray of the tile reaches before its bound;
    /// sets the box's nearest depth (the traversal's front-to-back key).
    [[nodiscard]] bool visible(const Box& box, double& near) const {
        Double4 value = side_c_;
        for (int k = 0; k < 3; ++k) {
            const Double4 lo = Double4{} + double(box.lo[k]), hi = Double4{} + double(box.hi[k]);
            value += side_a_[k] * (side_hi_[k] ? hi : lo);  // each plane's farthest corner
        }
        const Mask4 out = value < side_floor_;
        if (out[0] | out[1] | out[2] | out[3]) return false;
        near = depth_.c + depth_.min_over(box) - depth_.slack;
        return near <= far_;
    }

    /// The farthest depth any ray of the tile still searches (rounded up).
    void update_far() {
        double far = 0;
        for (int64_t j = 0, n = width_ * height_; j < n; ++j) far = std::max(far, bound_[j] * scale_[j]);
        far_ = far * (1 + 1e-12) + depth_.slack;
    }

    void traverse(const CameraRays::TilePixels& p) {
        const double m = map_.margin;
        const Plane side[4] = {at_least(map_.col, map_.col0, double(p.i0) - m), at_most(map_.col, map_.col0, double(p.i1) + m),
                               at_least(map_.row, map_.row0, double(p.r0) - m), at_most(map_.row, map_.row0, double(p.r1) + m)};
        for (int h = 0; h < 4; ++h) {
            side_c_[h] = side[h].c;
            side_floor_[h] = -side[h].slack;
            for (int k = 0; k < 3; ++k) {
                side_a_[k][h] = side[h].a[k];
                side_hi_[k][h] = side[h].a[k] >= 0 ? -1 : 0;
            }
        }
        update_far();
        struct Pending {
            uint32_t node;
            double near;
        } stack[128];
        int top = 0;
        double near;
        if (!visible(scene_.nodes[0].box, near)) return;
        uint32_t current = 0;
        for (;;) {
            const Node& node = scene_.nodes[current];
            if (node.is_leaf()) {
                bool changed = false;
                for (uint32_t i = node.index, end = node.index + node.count; i < end; ++i) changed |= test(i);
                if (changed) update_far();
            } else {
                const uint32_t left = node.index;
                double nl, nr;
                const bool vl = visible(scene_.nodes[left].box, nl), vr = visible(scene_.nodes[left + 1].box, nr);
                if (vl || vr) {
                    uint32_t first = left, second = left + 1;
                    if (!vl || (vr && nr < nl)) {
                        std::swap(first, second);
                        std::swap(nl, nr);
                    }
                    if (vl && vr) stack[top++] = {second, nr};
                    current = first;
                    continue;
                }
            }
            do {  // pop, skipping nodes that now lie beyond every ray's bound
                if (top == 0) return;
                --top;
            } while (stack[top].near > far_);
            current = stack[top].node;
        }
    }

    /// Tests triangle i on the tile's pixels its projection can cover; true when a ray's
    /// bound moved.
    bool test(uint32_t i) {
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(i);
        const float *a = projected_[tri[0]], *b = projected_[tri[1]], *c = projected_[tri[2]];
        const double near = std::min(a[2], std::min(b[2], c[2]));
        if (near - 0x1p-23 * std::fabs(near) > far_) return false;  // behind what every ray found
        int64_t c0 = 0, c1 = width_ - 1, q0 = 0, q1 = height_ - 1;
        if (a[0] == a[0] && b[0] == b[0] && c[0] == c[0]) {  // all three project (no NaN)
            const float lo_c = std::min(a[0], std::min(b[0], c[0])), hi_c = std::max(a[0], std::max(b[0], c[0]));
            const float lo_r = std::min(a[1], std::min(b[1], c[1])), hi_r = std::max(a[1], std::max(b[1], c[1]));
            // the projection's own margin, plus the rounding to single precision
            const double mc = rect_margin_ + 0x1p-23 * double(std::max(std::fabs(lo_c), std::fabs(hi_c)));
            const double mr = rect_margin_ + 0x1p-23 * double(std::max(std::fabs(lo_r), std::fabs(hi_r)));
            c0 = first_at_least(double(lo_c) - mc - double(i0_), width_);
            c1 = last_at_most(double(hi_c) + mc - double(i0_), width_);
            q0 = first_at_least(double(lo_r) - mr - double(r0_), height_);
            q1 = last_at_most(double(hi_r) + mr - double(r0_), height_);
        }
        bool changed = false;
        for (int64_t r = q0; r <= q1; ++r)
            for (int64_t c = c0; c <= c1; ++c) {
                const int64_t j = c + r * width_;
                if (!kernel_[j]) make_ray(j);
                const double before = bound_[j];
                test_triangle(*kernel_[j], scene_, i, ray_[j].tmin, bound_[j], hit_[j]);
                changed |= bound_[j] != before;
            }
        return changed;
    }

    void make_ray(int64_t j) {
        ray_[j] = rays_.ray(std::size_t((i0_ + j % width_) + (r0_ + j / width_) * int64_t(rays_.spec().nx)));
        kernel_[j].emplace(ray_[j], context_);
        bound_[j] = ray_[j].tmax;
        scale_[j] = dot(map_.depth, ray_[j].dir);  // depth per unit of t
    }

    /// First integer >= x within [0, n) (0 when x is below or NaN, n when above).
    static int64_t first_at_least(double x, int64_t n) {
        if (!(x > 0)) return 0;
        return x >= double(n) ? n : int64_t(std::ceil(x));
    }
    /// Last integer <= x within [0, n) (-1 when x is below, n - 1 when above or NaN).
    static int64_t last_at_most(double x, int64_t n) {
        if (x < 0) return -1;
        return !(x < double(n - 1)) ? n - 1 : int64_t(std::floor(x));
    }

    const Scene& scene_;
    const CameraRays& rays_;
    const ProjectedPoints& projected_;
    CastContext context_;
    CameraRays::PixelMap map_;
    using PixelMap = CameraRays::PixelMap;
    double to_anchor_[3], reach_[3], rect_margin_;
    Plane depth_;
    Double4 side_c_, side_floor_, side_a_[3];  // the side planes, one per lane
    Mask4 side_hi_[3];                         // lanes whose plane takes the box's hi corner on axis k
    double far_ = HUGE_VAL;
    int64_t i0_ = 0, r0_ = 0, width_ = 0, height_ = 0;
    std::vector<Ray> ray_;
    std::vector<std::optional<Kernel>> kernel_;
    std::vector<Hit<Real>> hit_;
    std::vector<double> bound_, scale_;
};

}  // namespace vrc
