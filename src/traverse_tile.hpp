// Coherent camera rays. Through a BVH, each tile finds its entry node, then its 8x8-pixel
// packets traverse together: nodes are culled once per packet against its frustum and
// against the farthest depth its rays still search, and a leaf's triangles are tested
// only on the pixels whose centres their projection can cover. On a flat scene (no BVH)
// a tile takes the triangles binned to it instead (bin_triangles.hpp). The ray-triangle
// test itself is the per-ray one (test_triangle), so every result equals the ray-by-ray
// traversal's; only the work of finding candidates is shared. Frustum and occlusion
// culling of a ray packet follow Reshetov, Soupikov and Hurley, "Multi-level ray tracing
// algorithm" (SIGGRAPH 2005), and Wald, Boulos and Shirley, "Ray tracing deformable scenes
// using dynamic bounding volume hierarchies" (ACM TOG 2007).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>
#if defined(__AVX__)
#include <immintrin.h>
#endif

#include "camera_rays.hpp"
#include "bin_triangles.hpp"
#include "projected_points.hpp"
#include "traverse.hpp"

namespace vrc {

/// Four doubles (GCC/Clang vector extension: AVX where the CPU has it, SSE2 otherwise):
/// the tile's four side planes evaluated at once.
using Double4 = double __attribute__((vector_size(32)));
using Mask4 = int64_t __attribute__((vector_size(32)));

/// Whether any lane of a comparison holds.
inline bool any(Mask4 m) {
#if defined(__AVX__)
    return _mm256_movemask_pd(_mm256_castsi256_pd(__m256i(m))) != 0;
#else
    return (m[0] | m[1] | m[2] | m[3]) != 0;
#endif
}

template <template <class> class KernelT, class Real>
class TileTracer {
    using Kernel = KernelT<Real>;
    static constexpr double kEps = std::numeric_limits<double>::epsilon();

    /// a.q + c >= -slack for every point q = P - eye a ray of the tile can reach, where
    /// c folds in the plane's constant and a.(anchor - eye); P - eye = (anchor - eye) + rel
    /// for a box corner rel (boxes are stored relative to the scene's anchor).
    struct Plane {
        double a[3], c, slack;
    };

   public:
    TileTracer(const Scene& scene, const CameraRays& rays, const ProjectedPoints& projected, const CastContext& context)
        : scene_(scene), rays_(rays), projected_(projected), context_(context), map_(rays.pixel_map()) {
        const int64_t n = CameraRays::kTile * CameraRays::kTile;
        ray_.resize(n);
        kernel_.resize(n);
        hit_.resize(n);
        bound_.resize(n);
        scale_.resize(n);
        depth_ = plane(map_.depth, 0);
        // lane 0: the depth at a box's farthest corner; lane 1: minus the depth at its nearest
        for (int k = 0; k < 3; ++k) {
            depth_a_[k] = Double4{depth_.a[k], -depth_.a[k], 0, 0};
            depth_hi_[k] = Mask4{depth_.a[k] >= 0 ? -1 : 0, depth_.a[k] >= 0 ? 0 : -1, 0, 0};
        }
    }

    /// Rays go through the BVH in square packets of kPacket x kPacket pixels: small enough
    /// that a packet's rays usually all hit and end close in depth (what occlusion culling
    /// needs), large enough to share the node tests. Frog contour at 1024x1024
    /// (benchmarks/instructions.py): 505, 472 and 591 instructions per ray for 4, 8 and 16.
    static constexpr int64_t kPacket = 8;

    /// Traces the tile's rays, packet by packet, and calls store(pixel, ray, hit) for each.
    template <class Store>
    void trace(std::size_t tile, Store&& store) {
        const CameraRays::TilePixels t = rays_.tile_pixels(tile);
        const uint32_t entry = rays_.tile_may_hit(tile) && !scene_.nodes.empty() ? entry_node(t) : kNoNode;
        if (entry == kNoNode) {  // nothing in the tile's frustum: misses, no rays made
            const int64_t nx = int64_t(rays_.spec().nx);
            for (int64_t r = t.r0; r <= t.r1; ++r)
                for (int64_t i = t.i0; i <= t.i1; ++i) store(std::size_t(i + r * nx), Ray{}, Hit<Real>{});
            return;
        }
        for (int64_t r = t.r0; r <= t.r1; r += kPacket)
            for (int64_t i = t.i0; i <= t.i1; i += kPacket)
                trace({i, std::min(i + kPacket - 1, t.i1), r, std::min(r + kPacket - 1, t.r1)}, entry, store);
    }

    /// A flat scene's tile (no BVH): its binned triangles (`begin` to `end`, see
    /// bin_triangles.hpp), then those with no usable projection (`unknown`), which are
    /// tested on the whole tile unless the tile's frustum separates them.
    template <class Store>
    void trace_bin(std::size_t tile, const TriangleBins::Entry* begin, const TriangleBins::Entry* end,
                   const std::vector<uint32_t>& unknown, Store&& store) {
        const CameraRays::TilePixels p = rays_.tile_pixels(tile);
        start(p);
        if (rays_.tile_may_hit(tile)) {
            for (const TriangleBins::Entry* e = begin; e != end; ++e)
                test_pixels(e->triangle, {e->c0, e->c1, e->r0, e->r1, e->near});
            if (!unknown.empty()) set_sides(p);
            for (uint32_t i : unknown)
                if (!separated(i)) test_pixels(i, {0, width_ - 1, 0, height_ - 1});
        }
        finish(store);
    }

   private:
    template <class Store>
    void trace(const CameraRays::TilePixels& p, uint32_t entry, Store& store) {
        start(p);
        traverse(p, entry);
        finish(store);
    }

    static constexpr uint32_t kNoNode = UINT32_MAX;

    /// The tile's entry point (Reshetov et al. 2005): the deepest node whose subtree holds
    /// every node the tile's frustum meets, so its packets skip the levels above; kNoNode
    /// when the frustum meets none.
    uint32_t entry_node(const CameraRays::TilePixels& t) {
        set_sides(t);
        far_ = HUGE_VAL;
        double near;
        if (!visible(scene_.nodes[0].box, near)) return kNoNode;
        uint32_t current = 0;
        while (!scene_.nodes[current].is_leaf()) {
            const uint32_t left = scene_.nodes[current].index;
            const bool vl = visible(scene_.nodes[left].box, near), vr = visible(scene_.nodes[left + 1].box, near);
            if (vl == vr) return vl ? current : kNoNode;
            current = vl ? left : left + 1;
        }
        return current;
    }

    /// Empties the rays of the block p; they are made when first tested (most blocks of a
    /// sparse frame see no triangle).
    void start(const CameraRays::TilePixels& p) {
        i0_ = p.i0;
        r0_ = p.r0;
        width_ = p.i1 - p.i0 + 1;
        height_ = p.r1 - p.r0 + 1;
        for (int64_t j = 0, n = width_ * height_; j < n; ++j) {
            kernel_[j].reset();
            hit_[j] = Hit<Real>{};
            bound_[j] = rays_.spec().far;  // a depth until the ray exists, then its t
            scale_[j] = 1;
        }
        far_ = HUGE_VAL;
    }

    template <class Store>
    void finish(Store& store) {
        for (int64_t j = 0, n = width_ * height_; j < n; ++j) store(pixel(j), ray_[j], hit_[j]);  // ray_ read on hits only
    }

    /// The image pixel of the block's j-th ray.
    [[nodiscard]] std::size_t pixel(int64_t j) const {
        return std::size_t((i0_ + j % width_) + (r0_ + j / width_) * int64_t(rays_.spec().nx));
    }

    /// Half-space a.q + b >= 0 of q = P - eye, with its rounding slack over the scene.
    [[nodiscard]] Plane plane(const double a[3], double b) const {
        Plane h;
        double size = std::fabs(b);
        h.c = b;
        for (int k = 0; k < 3; ++k) {
            h.a[k] = a[k];
            h.c += a[k] * projected_.to_anchor()[k];
            size += std::fabs(a[k]) * (std::fabs(projected_.to_anchor()[k]) + projected_.reach()[k]);
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
            const double l = box.lo[k], h = box.hi[k];
            value += side_a_[k] * (side_hi_[k] ? Double4{h, h, h, h} : Double4{l, l, l, l});  // farthest corners
        }
        if (any(value < side_floor_)) return false;
        Double4 depth = Double4{depth_.c, -depth_.c, 0, 0};
        for (int k = 0; k < 3; ++k) {
            const double l = box.lo[k], h = box.hi[k];
            depth += depth_a_[k] * (depth_hi_[k] ? Double4{h, h, h, h} : Double4{l, l, l, l});
        }
        // The side planes pass through a pinhole's eye, so they also admit the mirror image
        // of the frustum behind it: a box wholly nearer than the near plane is culled here.
        if (depth[0] + depth_.slack + projected_.depth_slack() < rays_.spec().near) return false;
        near = -depth[1] - depth_.slack;
        return near <= far_;
    }

    /// The farthest depth any ray of the tile still searches (rounded up).
    void update_far() {
        double far = 0;
        for (int64_t j = 0, n = width_ * height_; j < n; ++j) far = std::max(far, bound_[j] * scale_[j]);
        far_ = far * (1 + 1e-12) + depth_.slack + projected_.depth_slack();
    }

    /// The block's four side planes, one per lane.
    void set_sides(const CameraRays::TilePixels& p) {
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
    }

    /// Whether one side plane has all three points of triangle i outside.
    [[nodiscard]] bool separated(uint32_t i) const {
        Mask4 all_out = Mask4{} - 1;
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(i);
        for (int v = 0; v < 3; ++v) {
            const double* p = scene_.point(tri[v]);
            Double4 value = side_c_;
            for (int k = 0; k < 3; ++k)  // relative to the anchor, as the planes' constants are
                value += side_a_[k] * (p[k] - scene_.anchor[k]);
            all_out &= value < side_floor_;
        }
        return any(all_out);
    }

    void traverse(const CameraRays::TilePixels& p, uint32_t entry) {
        set_sides(p);
        update_far();
        struct Pending {
            uint32_t node;
            double near;
        } stack[128];
        int top = 0;
        double near;
        if (!visible(scene_.nodes[entry].box, near)) return;
        uint32_t current = entry;
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
        PixelRect rect{0, width_ - 1, 0, height_ - 1};
        const auto reach = projected_.rect(scene_.triangles.data() + 3 * std::size_t(i), i0_, r0_, width_, height_,
                                           rays_.spec().near, far_, rect);
        return reach != ProjectedPoints::Reach::none && test_pixels(i, rect);
    }

    /// Tests triangle i on the block's pixels in `rect`; true when a ray's bound moved.
    bool test_pixels(uint32_t i, const PixelRect& rect) {
        bool changed = false;
        for (int64_t r = rect.r0; r <= rect.r1; ++r)
            for (int64_t c = rect.c0; c <= rect.c1; ++c) {
                const int64_t j = c + r * width_;
                if (rect.near - projected_.depth_slack() > bound_[j] * scale_[j] * (1 + 1e-12)) continue;  // beyond this ray's hit
                if (!kernel_[j]) make_ray(j);
                const double before = bound_[j];
                test_triangle(*kernel_[j], scene_, i, ray_[j].tmin, bound_[j], hit_[j]);
                changed |= bound_[j] != before;
            }
        return changed;
    }

    void make_ray(int64_t j) {
        ray_[j] = rays_.ray(pixel(j));
        kernel_[j].emplace(ray_[j], context_);
        bound_[j] = ray_[j].tmax;
        scale_[j] = dot(map_.depth, ray_[j].dir);  // depth per unit of t
    }

    const Scene& scene_;
    const CameraRays& rays_;
    const ProjectedPoints& projected_;
    CastContext context_;
    CameraRays::PixelMap map_;
    Plane depth_;
    Double4 depth_a_[3];  // the depth plane's farthest and nearest corners, lanes 0 and 1
    Mask4 depth_hi_[3];
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
