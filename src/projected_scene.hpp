// A scene seen from one camera, prepared once per cast by all render workers: every point
// projected into the image, from the points each triangle's pixel rectangle and nearest
// depth, and through a BVH each camera-tree node's rectangle (holding its triangles').
// The tile tracer culls nodes and triangles against a packet with a few integer compares
// instead of plane tests, and a node's rectangle is tighter than its box's projection.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <thread>
#include <utility>
#include <vector>
#if defined(__SSE4_1__)
#include <immintrin.h>
#endif

#include "bvh.hpp"
#include "camera_rays.hpp"
#include "exact_sign.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// Pixels [c0, c1] x [r0, r1] of the image (inclusive) that may see something, none of it
/// nearer than `near`. Empty is c0 = r0 = kMaxPixels > c1 = r1 = 0, the identity of
/// `join` and never overlapping a block, so images are at most kMaxPixels wide and high.
struct ImageRect {
    static constexpr int64_t kMaxPixels = 65535;
    uint16_t c0, c1, r0, r1;
    float near;

    [[nodiscard]] bool empty() const { return c0 > c1; }
    void join(const ImageRect& o) {
        c0 = std::min(c0, o.c0), c1 = std::max(c1, o.c1);
        r0 = std::min(r0, o.r0), r1 = std::max(r1, o.r1);
        near = std::min(near, o.near);
    }
};
constexpr ImageRect kNoPixels{uint16_t(ImageRect::kMaxPixels), 0, uint16_t(ImageRect::kMaxPixels), 0, HUGE_VALF};

/// The pixels whose rays may hit a triangle, finer than its rectangle: a pixel centre p
/// is rejected only when it lies outside the triangle's projection by more than `margin`
/// (the rectangle's, plus the single-precision rounding of points outside the image).
/// Why that is safe: the exact projection p* of the pixel's ray lies within the margin of
/// p, and the triangle's exact projected points A', B', C' within it of the stored A, B, C.
/// If p* = aA' + bB' + cC' (a, b, c >= 0, summing to 1) then p = aA + bB + cC + e with
/// |e| <= margin in each coordinate, so the edge function of AB at p is c D + (B - A) x e,
/// D = (B - A) x (C - A); likewise for BC (a D) and CA (b D). Every edge function is
/// therefore >= -margin (|x| + |y| of its edge) when D >= 0, or all are <= +that when
/// D <= 0; a pixel failing both cannot be hit, whatever the triangle's orientation.
/// Evaluated from the stored floats with a slack for that rounding too, for pixel centres
/// within the margin of the points' box (those of the triangle's rectangle). A triangle
/// with a point of no usable projection keeps every pixel.
class Footprint {
   public:
    /// What a pixel's ray can hit: nothing, maybe the triangle, or the triangle surely
    /// (its centre lies inside every edge by more than the slack: a likely hit, see
    /// bin_triangles.hpp; never claimed without SSE4.1).
    enum Cover { kNone, kMay, kInside };
#if defined(__SSE4_1__)
    /// From the projected points (column, row, depth, flag), their box [lo, hi], the
    /// margin and the sure-hit test's (ProjectedScene::sure_margin).
    Footprint(__m128 pa, __m128 pb, __m128 pc, __m128 lo, __m128 hi, float margin, float sure_margin)
        : known_(_mm_cvtss_f32(_mm_shuffle_ps(hi, hi, 3)) == 0) {
        const __m128 abs_mask = _mm_castsi128_ps(_mm_set1_epi32(INT32_MAX));
        // Edge k runs from point k to point k + 1 (lane 3 repeats lane 2): its start (x, y)
        // and its vector (ex, ey).
        const __m128 ab = _mm_unpacklo_ps(pa, pb), bc = _mm_unpacklo_ps(pb, pc);
        x_ = _mm_shuffle_ps(ab, pc, _MM_SHUFFLE(0, 0, 1, 0)), y_ = _mm_shuffle_ps(ab, pc, _MM_SHUFFLE(1, 1, 3, 2));
        ex_ = _mm_sub_ps(_mm_shuffle_ps(bc, pa, _MM_SHUFFLE(0, 0, 1, 0)), x_);
        ey_ = _mm_sub_ps(_mm_shuffle_ps(bc, pa, _MM_SHUFFLE(1, 1, 3, 2)), y_);
        // The slack m (|ex| + |ey|) needs m >= the margin, plus 2^-23 size (the stored
        // rounding of points beyond the image; the margin covers those within it) and
        // 2^-49 max(size, 2^16) (the points' rounding in the exact argument), plus this
        // test's own rounding: under 5 roundings of |ex dy| + |ey dx|, where |dx|, |dy| <=
        // 2 size + margin for a centre within the margin of the box. All of it fits in
        // m = 1.01 margin + 2^-20 (3 size + margin + 2), whose own rounding the 1.01 covers.
        const __m128 big = _mm_max_ps(_mm_and_ps(lo, abs_mask), _mm_and_ps(hi, abs_mask));
        const float size = std::max(_mm_cvtss_f32(big), _mm_cvtss_f32(_mm_shuffle_ps(big, big, 1)));
        const float m = 1.01f * margin + 0x1p-20f * (3 * size + margin + 2);
        slack_ = _mm_add_ps(_mm_mul_ps(_mm_set1_ps(m), _mm_add_ps(_mm_and_ps(ex_, abs_mask), _mm_and_ps(ey_, abs_mask))),
                            _mm_set1_ps(0x1p-120f));  // (products that underflow)
        minus_slack_ = _mm_xor_ps(slack_, _mm_set1_ps(-0.0f));
        const __m128 extent = _mm_sub_ps(hi, lo);
        const float reach = _mm_cvtss_f32(extent) + _mm_cvtss_f32(_mm_shuffle_ps(extent, extent, 1)) + 2 * margin;
        const __m128 edge = _mm_add_ps(_mm_and_ps(ex_, abs_mask), _mm_and_ps(ey_, abs_mask));
        sure_slack_ = sure_slack(edge, _mm_set1_ps(sure_margin + 0x1p-23f * size), _mm_set1_ps(reach));
    }
    /// The sure-hit test's bound on an edge function (see ProjectedScene::SureHits) from
    /// |ex| + |ey| of the edge (`edge`), M (`m`) and `reach`, the width plus height of the
    /// points' box plus twice the margin: a pixel centre of the triangle's rectangle lies
    /// within it of any of the points in the 1-norm. M |B - A| + 2M reach + 4M^2, plus the
    /// single-precision edge function's rounding: under 5 roundings of |ex dy| + |ey dx|
    /// (ex, ey, dy = r - y, dx = c - x and the products each rounded once, then their
    /// difference), at most 2^-21 |B - A| reach. Widened for its own roundings (of positive
    /// terms), and by 2^-120 for products that underflow.
    template <class V>
    [[nodiscard]] static V sure_slack(V edge, V m, V reach) {
        const auto add = [](V a, V b) { if constexpr (sizeof(V) == 16) return _mm_add_ps(a, b); else return _mm256_add_ps(a, b); };
        const auto mul = [](V a, V b) { if constexpr (sizeof(V) == 16) return _mm_mul_ps(a, b); else return _mm256_mul_ps(a, b); };
        const auto set = [](float x) { if constexpr (sizeof(V) == 16) return _mm_set1_ps(x); else return _mm256_set1_ps(x); };
        const V bound = add(mul(edge, add(m, mul(set(0x1p-21f), reach))), mul(m, add(mul(set(2), reach), mul(set(4), m))));
        return add(mul(bound, set(1 + 0x1p-18f)), set(0x1p-120f));
    }
    /// Row r's part of the edge functions, shared by the pixels of a row.
    [[nodiscard]] __m128 row(int64_t r) const { return _mm_mul_ps(ex_, _mm_sub_ps(_mm_set1_ps(float(r)), y_)); }
    /// What the ray of the pixel at column `col` of a row (its `row` part) can hit.
    [[nodiscard]] Cover cover(int64_t col, __m128 row) const {
        if (!known_) return kMay;
        const __m128 e = _mm_sub_ps(row, _mm_mul_ps(ey_, _mm_sub_ps(_mm_set1_ps(float(col)), x_)));
        const int below = _mm_movemask_ps(_mm_cmplt_ps(e, minus_slack_)), above = _mm_movemask_ps(_mm_cmpgt_ps(e, slack_));
        if (below != 0 && above != 0) return kNone;
        return below == 15 || above == 15 ? kInside : kMay;
    }
    [[nodiscard]] bool may_cover(int64_t col, int64_t r) const { return cover(col, row(r)) != kNone; }
#if defined(__AVX2__)
    /// may_cover of the eight pixels at columns col .. col + 7 of row r, as bits: cover's
    /// float operations, an edge's eight pixels in the lanes of one register, so each lane
    /// decides as cover does. Second, the pixels the triangle surely covers: every edge
    /// function beyond the sure-hit bound with one sign (only positive when not
    /// `either_side`; see ProjectedScene::SureHits, which also needs the depths).
    [[nodiscard]] std::pair<unsigned, unsigned> may_cover8(int64_t col, int64_t r, bool either_side) const {
        if (!known_) return {0xff, 0};
        const __m256 cols = _mm256_add_ps(_mm256_set1_ps(float(col)), _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7));
        const __m128 at_row = row(r);
        __m256 below = _mm256_setzero_ps(), above = below;  // some edge below -slack, some above slack
        __m256 positive = _mm256_castsi256_ps(_mm256_set1_epi32(-1)), negative = positive;  // every edge beyond the sure bound
        for (int k = 0; k < 3; ++k) {
            const __m256 e = _mm256_sub_ps(lane(at_row, k), _mm256_mul_ps(lane(ey_, k), _mm256_sub_ps(cols, lane(x_, k))));
            below = _mm256_or_ps(below, _mm256_cmp_ps(e, lane(minus_slack_, k), _CMP_LT_OQ));
            above = _mm256_or_ps(above, _mm256_cmp_ps(e, lane(slack_, k), _CMP_GT_OQ));
            const __m256 sure = lane(sure_slack_, k);
            positive = _mm256_and_ps(positive, _mm256_cmp_ps(e, sure, _CMP_GT_OQ));
            negative = _mm256_and_ps(negative, _mm256_cmp_ps(e, _mm256_xor_ps(sure, _mm256_set1_ps(-0.0f)), _CMP_LT_OQ));
        }
        const unsigned sure = unsigned(_mm256_movemask_ps(positive)) | (either_side ? unsigned(_mm256_movemask_ps(negative)) : 0);
        return {~unsigned(_mm256_movemask_ps(_mm256_and_ps(below, above))) & 0xff, sure};
    }
#endif

   private:
#if defined(__AVX2__)
    /// Lane k of v in all eight lanes.
    [[nodiscard]] static __m256 lane(__m128 v, int k) {
        return _mm256_permutevar8x32_ps(_mm256_castps128_ps256(v), _mm256_set1_epi32(k));
    }
#endif
    __m128 x_, y_, ex_, ey_, slack_, minus_slack_, sure_slack_;
#else
    /// From the projected points (column, row, depth, flag); evaluated in double.
    Footprint(const float* a, const float* b, const float* c, float margin) : known_(a[3] + b[3] + c[3] == 0) {
        const float size = std::max(std::max(std::max(std::fabs(a[0]), std::fabs(a[1])), std::max(std::fabs(b[0]), std::fabs(b[1]))),
                                    std::max(std::fabs(c[0]), std::fabs(c[1])));
        // stored rounding of points beyond the image (the margin covers those within it),
        // then that of the edge functions below: under 8 roundings of |edge| |p - A|,
        // with |p - A| <= 2^16 + size
        const double m = double(margin) + 0x1p-23 * double(size) + 0x1p-49 * std::max(double(size), 65536.0);
        x_ = Double4{a[0], b[0], c[0], a[0]};  // lane k: edge from point k to point k + 1
        y_ = Double4{a[1], b[1], c[1], a[1]};
        ex_ = Double4{b[0], c[0], a[0], b[0]} - x_;
        ey_ = Double4{b[1], c[1], a[1], b[1]} - y_;
        const Double4 zero{};
        slack_ = m * ((ex_ < zero ? -ex_ : ex_) + (ey_ < zero ? -ey_ : ey_));
    }
    /// Whether the ray of the pixel centred at column col, row r may hit the triangle.
    [[nodiscard]] bool may_cover(int64_t col, int64_t r) const {
        const Double4 e = ex_ * (double(r) - y_) - ey_ * (double(col) - x_);
        return !known_ || !(any(e < -slack_) && any(e > slack_));
    }

   private:
    Double4 x_, y_, ex_, ey_, slack_;
#endif
    bool known_;
};

/// A camera-tree node (bvh.hpp) as a cast traverses it: its image rectangle beside its
/// links (as in Node), 16 bytes, so a node's children are tested and entered from one
/// cache line without touching the BVH's own boxes.
struct ProjectedNode {
    static constexpr std::size_t kMaxIndex = std::size_t(1) << 26;  // for the 26-bit index
    ImageRect rect;
    uint32_t index : 26;  ///< first child, or first triangle
    uint32_t count : 6;   ///< triangles of a leaf (at most CameraTree::kMaxLeaf), 0 for an inner node
};
static_assert(CameraTree::kMaxLeaf < 64, "a leaf's count is 6 bits");
static_assert(sizeof(ProjectedNode) == 16, "projected nodes are meant to be 16 bytes");

/// Each point's pixel column, row and depth for one camera, computed once per cast (the
/// workers share the points out): a point serves about six triangles. Single precision,
/// widened by its rounding where used. A point with no usable projection (near or behind a
/// pinhole's eye plane) is flagged instead. Through a BVH, also every node's ImageRect
/// (a triangle's is recomputed where needed: cheaper than storing it).
class ProjectedScene {
    static constexpr double kEps = std::numeric_limits<double>::epsilon();

   public:
    ProjectedScene(const Scene& scene, const CameraRays& rays)
        : scene_(scene), rays_(rays), map_(rays.pixel_map()) {
        const std::size_t n_points = scene.points.size() / 3, n_nodes = scene.has_bvh() ? scene.camera.nodes.size() : 0;
        memory_ = scene.scratch->take(n_points * 4 * sizeof(float) + n_nodes * sizeof(ProjectedNode));
        points_ = new (memory_.data.get()) float[4 * n_points];  // trivial types: no initialisation
        node_ = new (memory_.data.get() + n_points * 4 * sizeof(float)) ProjectedNode[n_nodes];
        if (!memory_.used)  // the links (the camera tree's) stay from one cast to the next
            for (std::size_t i = 0; i < n_nodes; ++i) node_[i].index = scene.camera.nodes[i].index, node_[i].count = scene.camera.nodes[i].count;
        memory_.used = true;
        if (n_nodes > 0) projected_ = std::make_unique<std::atomic<bool>[]>(scene.camera.subtrees.size());
        const CameraSpec& c = rays.spec();
        double depth_size = 0, parallel_size = std::fabs(map_.col0) + std::fabs(map_.row0);
        for (int k = 0; k < 3; ++k) {
            // farthest reach of the scene's box from the anchor on this axis
            double reach = std::max(std::fabs(double(scene.bounds.lo[k])), std::fabs(double(scene.bounds.hi[k])));
            if (!(reach < HUGE_VAL)) reach = 0;  // empty scene
            const double extent = std::fabs(scene.anchor[k] - c.eye[k]) + reach;  // bounds |P - eye| on axis k
            depth_size += std::fabs(map_.depth[k]) * extent;
            parallel_size += std::max(std::fabs(map_.col[k]), std::fabs(map_.row[k])) * extent;
        }
        // (a parallel ray's origin leaves the eye plane by its own rounding)
        const double eye = std::max(std::fabs(c.eye[0]), std::max(std::fabs(c.eye[1]), std::fabs(c.eye[2])));
        const double window = c.width + c.height + std::fabs(c.shift_x) + std::fabs(c.shift_y);
        depth_slack_ = 16 * kEps * (depth_size + (c.parallel ? eye + window : 0));
        // The projection's own margin (a parallel one's rounding grows with |P - eye|), plus
        // the single-precision roundings of a column or row (stored, then less the margin)
        // that can fall in the image: one farther out clamps to the border whatever its
        // rounding. Rounded up to single precision, as is twice the depth slack (at least
        // the smallest normal float, which covers a subnormal depth's rounding).
        const double projection_margin = map_.margin + (c.parallel ? 16 * kEps * parallel_size : 0);
        const double margin = projection_margin + 0x1p-21 * double(std::max(c.nx, c.ny) + 2);
        margin_ = round_up(margin);
        sure_margin_ = round_up(projection_margin);  // (the projection's own margin, without the storage's)
        slack_ = std::max(round_up(2 * depth_slack_), std::numeric_limits<float>::min());
        near_ = -round_up(-c.near), far_ = round_up(c.far);  // rounded outward
        // A triangle's depths must clear the camera's range by more than the kernel's and
        // the ray's t range's roundings (tiny beside 2^-20) for its hit to be sure (SureHits).
        sure_near_ = round_up(c.near + std::fabs(c.near) * 0x1p-20 + slack_);
        sure_far_ = std::isinf(c.far) ? HUGE_VALF : -round_up(-(c.far - std::fabs(c.far) * 0x1p-20 - slack_));
#if defined(__SSE4_1__)
        const float nx = float(c.nx), ny = float(c.ny);
        margin4_ = _mm_setr_ps(-margin_, margin_, -margin_, margin_);
        floor4_ = _mm_setr_ps(0, -1, 0, -1);
        ceil4_ = _mm_setr_ps(nx, nx - 1, ny, ny - 1);
        any4_ = _mm_setr_ps(0, nx - 1, 0, ny - 1);
        none4_ = _mm_setr_ps(float(ImageRect::kMaxPixels), 0, float(ImageRect::kMaxPixels), 0);
#endif
    }
    ~ProjectedScene() { scene_.scratch->give(std::move(memory_)); }
    ProjectedScene(const ProjectedScene&) = delete;
    ProjectedScene& operator=(const ProjectedScene&) = delete;

    /// Projects the points, with the other workers: each takes runs of them until none is
    /// left (not a fixed share, so a worker the machine holds up delays no one).
    void project() {
        const std::size_t n = scene_.points.size() / 3;
        for (std::size_t k; (k = next_run_.fetch_add(1)) * kRun < n;) project(k * kRun, std::min(n, (k + 1) * kRun));
    }

    /// Through a BVH, the points and the node rectangles: whole subtrees (called by every
    /// worker: each takes subtrees in the triangles' order until none is left), then the few
    /// nodes above them (`frame_top`, one worker, once every worker is done). A subtree's
    /// points (those its triangles use first, CameraTree::point_end) are projected, then,
    /// once the subtrees before it have projected theirs (its leaves also use some of
    /// those), its leaves are framed from them while they are still in cache, then its inner
    /// nodes from last to first, as every node's children follow it. A subtree whose box the
    /// camera cannot see (CameraRays::sees) is not framed: its root gets no pixels, so no
    /// tile visits its nodes, and only its points that later subtrees use are projected.
    void project_and_frame() {
        const CameraTree& tree = scene_.camera;
        std::size_t before = 0;  // subtrees this worker knows projected (a prefix)
        for (std::size_t k; (k = next_subtree_.fetch_add(1)) < tree.subtrees.size();) {
            const CameraTree::Subtree& t = tree.subtrees[k];
            const bool seen = rays_.sees(t.box, scene_.anchor);
            if (seen)
                project(k == 0 ? 0 : tree.point_end[tree.subtrees[k - 1].root], tree.point_end[t.root]);
            else
                for (uint32_t j = t.shared_begin; j < t.shared_end; ++j) project(tree.shared[j], tree.shared[j] + 1);
            projected_[k].store(true, std::memory_order_release);
            if (!seen) {
                node_[t.root].rect = kNoPixels;
                continue;
            }
            while (before < k) {
                if (projected_[before].load(std::memory_order_acquire))
                    ++before;
                else
                    std::this_thread::yield();
            }
            for (uint32_t i = t.first; i < t.end; ++i)
                if (node_[i].count != 0) frame_leaf(i);
            for (uint32_t i = t.end; i-- > t.first;)
                if (node_[i].count == 0) join_children(i);
            if (node_[t.root].count != 0) frame_leaf(t.root);
            else join_children(t.root);
        }
    }
    void frame_top() {
        const std::vector<uint32_t>& top = scene_.camera.top;
        for (auto i = top.rbegin(); i != top.rend(); ++i) join_children(*i);
    }

    enum class Reach { none, rect, unknown };
    /// The image pixels through which triangle `tri` may be hit, and its nearest depth:
    /// none (its projection misses the image, or its depths all lie outside [near, far]),
    /// rect, or unknown (a point has no usable projection: the rectangle of cone_rect).
    [[nodiscard]] Reach frame_triangle(const uint32_t tri[3], ImageRect& out) const {
#if defined(__SSE4_1__)
        const __m128 pa = _mm_load_ps((*this)[tri[0]]), pb = _mm_load_ps((*this)[tri[1]]), pc = _mm_load_ps((*this)[tri[2]]);
        const __m128 hi = _mm_max_ps(_mm_max_ps(pa, pb), pc);
        store(rect4(_mm_min_ps(_mm_min_ps(pa, pb), pc), hi, out.near), out);
        if (out.empty()) return Reach::none;
        const Reach reach = _mm_cvtss_f32(_mm_shuffle_ps(hi, hi, 3)) != 0 ? Reach::unknown : Reach::rect;
#else
        const Reach reach = frame_points(tri, tri + 3, out);
#endif
        if (reach != Reach::unknown) return reach;
        out = cone_rect(tri, out.near);
        return out.empty() ? Reach::none : Reach::unknown;
    }

    /// The pixels through which a triangle with a point of no usable projection (near or
    /// behind a pinhole's eye plane) may be hit, `near` its nearest depth: those whose
    /// centres lie in the image's part of the cone from the eye over the triangle. In the
    /// homogeneous pixel coordinates h = (column, row, 1) depth of a point relative to the
    /// eye (PixelMap: a linear map), a ray through pixel (c, r) hits the triangle ABC only
    /// if (c, r, 1) = x h_A + y h_B + z h_C with x, y, z >= 0, i.e. the edge functions
    /// (h_A x h_B) . (c, r, 1) and the other two all have the sign of det[h_A, h_B, h_C]
    /// (2D homogeneous rasterisation, Olano and Greer, "Triangle scan conversion using 2D
    /// homogeneous coordinates", Graphics Hardware 1997: no division by a depth, so points
    /// behind the eye need no clipping). The image's rectangle of pixel centres is clipped
    /// by the three half-planes widened by their roundings (the pixel ray's own margin, as
    /// Footprint's, times the edge's slope; 64 eps of the products' sizes for the points'
    /// and the products' roundings, far above them), and its box, widened by a millionth of
    /// a pixel for the clipping's roundings, is the rectangle. When the eye lies within
    /// rounding of the triangle's plane, the determinant's sign is taken exactly (the
    /// map's own determinant is far from zero), and exactly on it see `through_eye`.
    [[nodiscard]] ImageRect cone_rect(const uint32_t tri[3], float near) const {
        const CameraSpec& c = rays_.spec();
        const double last_col = double(c.nx) - 1, last_row = double(c.ny) - 1;
        const ImageRect every{0, uint16_t(last_col), 0, uint16_t(last_row), near};
        double h[3][3], size[3];
        for (int v = 0; v < 3; ++v) {
            const double* p = scene_.point(tri[v]);
            const double q[3] = {p[0] - c.eye[0], p[1] - c.eye[1], p[2] - c.eye[2]};
            h[v][0] = dot(map_.col, q), h[v][1] = dot(map_.row, q), h[v][2] = dot(map_.depth, q);
            size[v] = 0;
            for (int k = 0; k < 3; ++k)
                size[v] += (std::fabs(map_.col[k]) + std::fabs(map_.row[k]) + std::fabs(map_.depth[k])) * std::fabs(q[k]);
        }
        double edge[3][3], slack[3];
        for (int k = 0; k < 3; ++k) {
            const double *a = h[k], *b = h[(k + 1) % 3];
            edge[k][0] = a[1] * b[2] - a[2] * b[1], edge[k][1] = a[2] * b[0] - a[0] * b[2], edge[k][2] = a[0] * b[1] - a[1] * b[0];
            slack[k] = (std::fabs(edge[k][0]) + std::fabs(edge[k][1])) * map_.margin +
                       64 * kEps * size[k] * size[(k + 1) % 3] * (last_col + last_row + 3);
        }
        const double det = dot(edge[0], h[2]);
        double sign = det > 0 ? 1 : -1;
        if (!(std::fabs(det) > 64 * kEps * size[0] * size[1] * size[2])) {
            const int side = exact::volume(scene_.point(tri[0]), scene_.point(tri[1]), scene_.point(tri[2]), c.eye);
            if (side == 0) return through_eye(tri) ? every : kNoPixels;
            double row_depth[3];
            cross(map_.row, map_.depth, row_depth);
            sign = side * (dot(map_.col, row_depth) > 0 ? 1 : -1);
        }
        // Sutherland-Hodgman: each half-plane adds at most one corner to the four
        double x[8] = {0, last_col, last_col, 0}, y[8] = {0, 0, last_row, last_row};
        int n = 4;
        for (int k = 0; k < 3 && n > 0; ++k) {
            const auto f = [&](int i) { return sign * (edge[k][0] * x[i] + edge[k][1] * y[i] + edge[k][2]) + slack[k]; };
            double cx[8], cy[8], fv[8];
            for (int i = 0; i < n; ++i) fv[i] = f(i);
            int m = 0;
            for (int i = 0; i < n; ++i) {
                const int j = (i + 1) % n;
                if (fv[i] >= 0) cx[m] = x[i], cy[m] = y[i], ++m;
                if ((fv[i] >= 0) != (fv[j] >= 0)) {
                    const double t = fv[i] / (fv[i] - fv[j]);
                    cx[m] = x[i] + t * (x[j] - x[i]), cy[m] = y[i] + t * (y[j] - y[i]), ++m;
                }
            }
            std::copy(cx, cx + m, x), std::copy(cy, cy + m, y), n = m;
        }
        if (n == 0) return kNoPixels;
        constexpr double kRounding = 1e-6;
        const auto [c0, c1] = std::minmax_element(x, x + n);
        const auto [r0, r1] = std::minmax_element(y, y + n);
        const ImageRect rect{uint16_t(std::max(0.0, std::ceil(*c0 - kRounding))), uint16_t(std::min(last_col, std::floor(*c1 + kRounding))),
                             uint16_t(std::max(0.0, std::ceil(*r0 - kRounding))), uint16_t(std::min(last_row, std::floor(*r1 + kRounding))), near};
        return rect.empty() || rect.r0 > rect.r1 ? kNoPixels : rect;
    }

#if defined(__SSE4_1__)
    /// The pixels (c0, c1, r0, r1 as floats, clamped to [0, n] and [-1, n - 1]) whose
    /// centres lie within the margin of the box [lo, hi] of usable projected points: none
    /// when c0 > c1 or r0 > r1.
    [[nodiscard]] __m128 pixel_span(__m128 lo, __m128 hi) const {
        const __m128 v = _mm_add_ps(_mm_unpacklo_ps(lo, hi), margin4_);
        return _mm_min_ps(_mm_max_ps(_mm_blend_ps(_mm_ceil_ps(v), _mm_floor_ps(v), 0b1010), floor4_), ceil4_);
    }
#endif
    /// A lower bound on depths within [lo_z, hi_z] (stored point depths, see rect4), or
    /// HUGE_VALF when they all lie outside the camera's [near, far].
    [[nodiscard]] float near_bound(float lo_z, float hi_z) const {
        const auto [near, far] = depth_bounds(lo_z, hi_z);
        return near > far_ || far < near_ ? HUGE_VALF : near;
    }

    /// SureHits: whether the watertight kernel, in double, surely hits a triangle on the ray
    /// of a pixel, within the ray's t range, given bounds [near, far] on the triangle's
    /// depths (from `triangles8`): Footprint::may_cover8 and cover8 tell it with the edge
    /// functions they evaluate anyway, against a wider bound (Footprint::sure_slack), and
    /// sure_depths checks the depths.
    ///
    /// Why: the projection's margin bounds, per coordinate, the distance of the pixel centre
    /// p from the exact projection p* of its ray plus that of a point's projection from its
    /// exact one (CameraRays::PixelMap); with the stored single-precision rounding of the
    /// points (2^-24 of their largest coordinate, `size`; 2^-23 is allowed), M bounds both
    /// |p* - p| + |A' - A| and |A' - A| for each stored point A and its exact projection A'.
    /// For the edge from A to B, E(p) = (B - A) x (p - A) differs from the exact E'(p*) =
    /// (B' - A') x (p* - A') by (B - A) x (p* - p - A' + A) + (B' - B - A' + A) x (p - A) +
    /// the product of the two perturbations: at most M |B - A| + 2M |p - A| + 4M^2 (|.| the
    /// 1-norm). A pixel centre of the triangle's rectangle lies within the width plus height
    /// of the points' box plus twice the margin of A (and of any point) in the 1-norm, and E,
    /// evaluated in single precision from the stored floats, carries a rounding bounded
    /// with those (Footprint::sure_slack adds both). When all three edges clear
    /// that bound with one sign, every exact edge function at p* has that sign: the exact ray
    /// passes strictly inside the exact triangle (a central or parallel projection keeps the
    /// sign of det[A - O, B - O, d] for points in front). The kernel's edge functions take
    /// their exact signs (Watertight::exact_if_close), so it hits; and its t lies within the
    /// ray's range when the depths clear the camera's [near, far] (sure_near_, sure_far_).
    /// With back-face culling (not `either_side`): only when the edges are all positive. Columns grow
    /// to the right and rows upwards as the eye sees them, and a central or parallel
    /// projection keeps the orientation of points in front, so their sum, the projected
    /// (B - A) x (C - A), is then positive: the triangle's right-hand normal points at the
    /// eye, as the kernel's det > 0, and it is not culled.
    [[nodiscard]] bool sure_depths(float near, float far) const { return near > sure_near_ && far < sure_far_; }
    /// M less the points' storage rounding (see SureHits), rounded up to single precision.
    [[nodiscard]] float sure_margin() const { return sure_margin_; }

    /// Through a BVH, triangle i's rectangle (leaf order).
    [[nodiscard]] ImageRect triangle(uint32_t i) const {
        ImageRect rect;
        (void)frame_triangle(scene_.triangles.data() + 3 * std::size_t(i), rect);
        return rect;
    }

#if defined(__AVX2__)
    /// Eight triangles' rectangles at once, one lane each: (c0, c1, r0, r1) as floats and
    /// the nearest depth, as `triangle` computes them one at a time; and for Footprint's
    /// test, their projected points and which have a point with no usable projection.
    struct Rects8 {
        __m256 c0, c1, r0, r1, near, far, x[3], y[3], unknown;
    };
    /// Triangles first .. first + n - 1 (leaf order, 1 <= n <= 8; lanes from n on are
    /// empty). The same operations on the same floats as rect4, so the same rectangles;
    /// a leaf's triangles cost a few dozen vector operations per eight instead of a dozen
    /// scalar ones each. The points are loaded whole and transposed, not gathered: AVX2's
    /// gathers took 1.11x the time (benchmarks/compare_builds.py, frog at 1024x1024, on
    /// this AMD EPYC, where a gather is a long microcoded sequence).
    [[nodiscard]] Rects8 triangles8(uint32_t first, uint32_t n) const {
        const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), live = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(n)), lane);
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(first);
        Rects8 r;
        __m256 z[3], flag = _mm256_setzero_ps();
        for (int v = 0; v < 3; ++v) {
            // Triangle k's point in lane k: rows (column, row, depth, flag) of triangles k
            // and k + 4 side by side, transposed four at a time (lanes past n repeat the
            // last triangle: their rectangles are dropped).
            __m256 p[4];
            for (uint32_t k = 0; k < 4; ++k) {
                const float* a = (*this)[tri[3 * std::min(k, n - 1) + v]];
                const float* b = (*this)[tri[3 * std::min(k + 4, n - 1) + v]];
                p[k] = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(a)), _mm_load_ps(b), 1);
            }
            const __m256 t0 = _mm256_unpacklo_ps(p[0], p[1]), t1 = _mm256_unpackhi_ps(p[0], p[1]);
            const __m256 t2 = _mm256_unpacklo_ps(p[2], p[3]), t3 = _mm256_unpackhi_ps(p[2], p[3]);
            r.x[v] = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
            r.y[v] = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
            z[v] = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
            flag = _mm256_max_ps(flag, _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2)));
        }
        const auto lowest = [](const __m256 p[3]) { return _mm256_min_ps(_mm256_min_ps(p[0], p[1]), p[2]); };
        const auto highest = [](const __m256 p[3]) { return _mm256_max_ps(_mm256_max_ps(p[0], p[1]), p[2]); };
        const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(INT32_MAX)), rel = _mm256_set1_ps(0x1p-21f),
                     slack = _mm256_set1_ps(slack_), margin = _mm256_set1_ps(margin_);
        const __m256 lo_z = lowest(z), hi_z = highest(z);
        r.near = _mm256_sub_ps(lo_z, _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(lo_z, abs_mask), rel), slack));
        r.far = _mm256_add_ps(hi_z, _mm256_add_ps(_mm256_mul_ps(_mm256_and_ps(hi_z, abs_mask), rel), slack));
        const CameraSpec& c = rays_.spec();
        const __m256 zero = _mm256_setzero_ps();
        r.unknown = _mm256_cmp_ps(flag, zero, _CMP_NEQ_UQ);
        const auto span = [&](const __m256 p[3], float size, __m256& first_pixel, __m256& last_pixel) {
            const __m256 n_pixels = _mm256_set1_ps(size), last = _mm256_set1_ps(size - 1);
            first_pixel = _mm256_min_ps(_mm256_max_ps(_mm256_ceil_ps(_mm256_sub_ps(lowest(p), margin)), zero), n_pixels);
            last_pixel = _mm256_min_ps(_mm256_max_ps(_mm256_floor_ps(_mm256_add_ps(highest(p), margin)), _mm256_set1_ps(-1)), last);
            first_pixel = _mm256_blendv_ps(first_pixel, zero, r.unknown);  // a point with no projection: every pixel
            last_pixel = _mm256_blendv_ps(last_pixel, last, r.unknown);
        };
        span(r.x, float(c.nx), r.c0, r.c1);
        span(r.y, float(c.ny), r.r0, r.r1);
        const __m256 empty = _mm256_or_ps(
            _mm256_or_ps(_mm256_or_ps(_mm256_cmp_ps(r.c0, r.c1, _CMP_GT_OQ), _mm256_cmp_ps(r.r0, r.r1, _CMP_GT_OQ)),
                         _mm256_or_ps(_mm256_cmp_ps(r.near, _mm256_set1_ps(far_), _CMP_GT_OQ),
                                      _mm256_cmp_ps(r.far, _mm256_set1_ps(near_), _CMP_LT_OQ))),
            _mm256_castsi256_ps(_mm256_xor_si256(live, _mm256_set1_epi32(-1))));
        const __m256 none = _mm256_set1_ps(float(ImageRect::kMaxPixels));
        r.c0 = _mm256_blendv_ps(r.c0, none, empty), r.c1 = _mm256_blendv_ps(r.c1, zero, empty);
        r.r0 = _mm256_blendv_ps(r.r0, none, empty), r.r1 = _mm256_blendv_ps(r.r1, zero, empty);
        r.near = _mm256_blendv_ps(r.near, _mm256_set1_ps(HUGE_VALF), empty);
        if (const unsigned cones = unsigned(_mm256_movemask_ps(_mm256_andnot_ps(empty, r.unknown)))) with_cones(r, first, cones);
        return r;
    }
    /// Lanes `cones` of r (triangles from `first` with a point of no usable projection):
    /// their rectangles from cone_rect instead of the whole image.
    void with_cones(Rects8& r, uint32_t first, unsigned cones) const {
        alignas(32) float c0[8], c1[8], r0[8], r1[8], near[8];
        _mm256_store_ps(c0, r.c0), _mm256_store_ps(c1, r.c1), _mm256_store_ps(r0, r.r0), _mm256_store_ps(r1, r.r1);
        _mm256_store_ps(near, r.near);
        for (; cones != 0; cones &= cones - 1) {
            const int k = __builtin_ctz(cones);
            const ImageRect rect = cone_rect(scene_.triangles.data() + 3 * std::size_t(first + k), near[k]);
            c0[k] = float(rect.c0), c1[k] = float(rect.c1), r0[k] = float(rect.r0), r1[k] = float(rect.r1);
            if (rect.empty()) near[k] = HUGE_VALF;
        }
        r.c0 = _mm256_load_ps(c0), r.c1 = _mm256_load_ps(c1), r.r0 = _mm256_load_ps(r0), r.r1 = _mm256_load_ps(r1);
        r.near = _mm256_load_ps(near);
    }
    /// Footprint's test and the sure-hit test (see SureHits) of the eight triangles of `q`
    /// on the rays of kPixels pixels each, lane k's p-th at (col[p], row[p]): which lanes
    /// may be hit there (`may[p]`), and which surely are (`sure[p]`; the positive side only
    /// unless `either_side`). Footprint's operations on the same floats, eight triangles
    /// at once.
    template <int kPixels>
    struct Cover8 {
        __m256 may[kPixels], sure[kPixels];
    };
    template <int kPixels>
    [[nodiscard]] Cover8<kPixels> cover8(const Rects8& q, const __m256 col[kPixels], const __m256 row[kPixels],
                                         bool either_side) const {
        const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(INT32_MAX));
        const auto abs = [&](__m256 v) { return _mm256_and_ps(v, abs_mask); };
        __m256 size = _mm256_setzero_ps();
        for (int v = 0; v < 3; ++v) size = _mm256_max_ps(size, _mm256_max_ps(abs(q.x[v]), abs(q.y[v])));
        const __m256 margin = _mm256_set1_ps(margin_);
        const __m256 m = _mm256_add_ps(
            _mm256_mul_ps(_mm256_set1_ps(1.01f), margin),
            _mm256_mul_ps(_mm256_set1_ps(0x1p-20f),
                          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(3), size), margin), _mm256_set1_ps(2))));
        const auto extent = [](const __m256 p[3]) {
            return _mm256_sub_ps(_mm256_max_ps(_mm256_max_ps(p[0], p[1]), p[2]), _mm256_min_ps(_mm256_min_ps(p[0], p[1]), p[2]));
        };
        const __m256 sure_m = _mm256_add_ps(_mm256_set1_ps(sure_margin_), _mm256_mul_ps(_mm256_set1_ps(0x1p-23f), size));
        const __m256 reach = _mm256_add_ps(_mm256_add_ps(extent(q.x), extent(q.y)), _mm256_add_ps(margin, margin));
        const __m256 all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        __m256 below[kPixels], above[kPixels], positive[kPixels], negative[kPixels];
        for (int p = 0; p < kPixels; ++p) below[p] = above[p] = _mm256_setzero_ps(), positive[p] = negative[p] = all;
        for (int k = 0; k < 3; ++k) {
            const __m256 ex = _mm256_sub_ps(q.x[(k + 1) % 3], q.x[k]), ey = _mm256_sub_ps(q.y[(k + 1) % 3], q.y[k]);
            const __m256 slack = _mm256_add_ps(_mm256_mul_ps(m, _mm256_add_ps(abs(ex), abs(ey))), _mm256_set1_ps(0x1p-120f));
            const __m256 minus_slack = _mm256_xor_ps(slack, _mm256_set1_ps(-0.0f));
            const __m256 sure = Footprint::sure_slack(_mm256_add_ps(abs(ex), abs(ey)), sure_m, reach), minus_sure = _mm256_xor_ps(sure, _mm256_set1_ps(-0.0f));
            for (int p = 0; p < kPixels; ++p) {
                const __m256 e = _mm256_sub_ps(_mm256_mul_ps(ex, _mm256_sub_ps(row[p], q.y[k])), _mm256_mul_ps(ey, _mm256_sub_ps(col[p], q.x[k])));
                below[p] = _mm256_or_ps(below[p], _mm256_cmp_ps(e, minus_slack, _CMP_LT_OQ));
                above[p] = _mm256_or_ps(above[p], _mm256_cmp_ps(e, slack, _CMP_GT_OQ));
                positive[p] = _mm256_and_ps(positive[p], _mm256_cmp_ps(e, sure, _CMP_GT_OQ));
                negative[p] = _mm256_and_ps(negative[p], _mm256_cmp_ps(e, minus_sure, _CMP_LT_OQ));
            }
        }
        const __m256 possible = _mm256_andnot_ps(q.unknown, _mm256_and_ps(_mm256_cmp_ps(q.near, _mm256_set1_ps(sure_near_), _CMP_GT_OQ),
                                                                          _mm256_cmp_ps(q.far, _mm256_set1_ps(sure_far_), _CMP_LT_OQ)));
        Cover8<kPixels> c;
        for (int p = 0; p < kPixels; ++p) {
            c.may[p] = _mm256_or_ps(q.unknown, _mm256_andnot_ps(_mm256_and_ps(below[p], above[p]), all));
            c.sure[p] = _mm256_and_ps(possible, either_side ? _mm256_or_ps(positive[p], negative[p]) : positive[p]);
        }
        return c;
    }
#endif

    /// Triangle i's footprint (leaf order; see Footprint).
    [[nodiscard]] Footprint footprint(uint32_t i) const {
        const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(i);
#if defined(__SSE4_1__)
        const __m128 pa = _mm_load_ps((*this)[tri[0]]), pb = _mm_load_ps((*this)[tri[1]]), pc = _mm_load_ps((*this)[tri[2]]);
        return Footprint(pa, pb, pc, _mm_min_ps(_mm_min_ps(pa, pb), pc), _mm_max_ps(_mm_max_ps(pa, pb), pc), margin_, sure_margin_);
#else
        return Footprint((*this)[tri[0]], (*this)[tri[1]], (*this)[tri[2]], margin_);
#endif
    }

    /// Column, row and depth of point i, and 1 when it has no usable projection (else 0).
    [[nodiscard]] const float* operator[](uint32_t i) const { return points_ + 4 * std::size_t(i); }
    /// Through a BVH, node i: its rectangle holds its triangles'.
    [[nodiscard]] const ProjectedNode& node(uint32_t i) const { return node_[i]; }
    /// Asks the cache for what entering node n reads first: its children, or a leaf's
    /// triangles (their points' indices).
    void prefetch(const ProjectedNode& n) const {
        if (n.count == 0) prefetch_line(node_ + n.index);
        else prefetch_line(scene_.triangles.data() + 3 * std::size_t(n.index));
    }
    /// Asks the cache for leaf n's triangles (their points' indices), every line of them.
    void prefetch_triangles(const ProjectedNode& n) const {
        prefetch_range(scene_.triangles.data() + 3 * std::size_t(n.index), 12 * std::size_t(n.count));
    }
    /// Asks the cache for the projected points of triangles first to first + count - 1.
    void prefetch_points(uint32_t first, uint32_t count) const {
        const uint32_t *p = scene_.triangles.data() + 3 * std::size_t(first), *end = p + 3 * count;
        for (; p != end; ++p) prefetch_line(points_ + 4 * std::size_t(*p));
    }
    [[nodiscard]] double depth_slack() const { return depth_slack_; }     ///< rounding of any depth
    [[nodiscard]] float margin() const { return margin_; }                ///< see Footprint

   private:
    /// Projects points i to end - 1.
    void project(std::size_t i, std::size_t end) {
#if defined(__AVX__)
        for (; i + 4 <= end; i += 4) project4(i);
#endif
        for (; i < end; ++i) {
            const double* p = scene_.point(uint32_t(i));
            const CameraSpec& c = rays_.spec();
            const double q[3] = {p[0] - c.eye[0], p[1] - c.eye[1], p[2] - c.eye[2]};
            const double depth = dot(map_.depth, q);
            const double den = c.parallel ? 1.0 : depth;
            float* out = points_ + 4 * i;
            out[2] = float(depth);
            out[3] = 0;
            if (!c.parallel && !(den > CameraRays::PixelMap::kMinDen * (std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2])))) {
                out[0] = out[1] = 0;
                out[3] = 1;  // no usable projection
                continue;
            }
            out[0] = float((dot(map_.col, q) + map_.col0) / den);
            out[1] = float((dot(map_.row, q) + map_.row0) / den);
        }
    }

#if defined(__AVX__)
    /// Points i to i + 3, as the loop in `project` does them one by one (the same
    /// operations in the same order: the same floats), four lanes at a time.
    void project4(std::size_t i) {
        const CameraSpec& c = rays_.spec();
        const double* p = scene_.point(uint32_t(i));
        const auto lanes = [](double a) { return _mm256_set1_pd(a); };
        const auto dot3 = [&](const double f[3], __m256d x, __m256d y, __m256d z) {
            return _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(lanes(f[0]), x), _mm256_mul_pd(lanes(f[1]), y)),
                                 _mm256_mul_pd(lanes(f[2]), z));
        };
        // the four points' coordinates, each axis in the lanes: three loads and five shuffles
        const __m256d a = _mm256_loadu_pd(p), b = _mm256_loadu_pd(p + 4), d = _mm256_loadu_pd(p + 8);
        const __m256d xy = _mm256_blend_pd(a, b, 0b1100), yz = _mm256_blend_pd(b, d, 0b1100);  // x0 y0 x2 y2, y1 z1 y3 z3
        const __m256d zx = _mm256_permute2f128_pd(a, d, 0x21);                                  // z0 x1 z2 x3
        const __m256d x = _mm256_sub_pd(_mm256_shuffle_pd(xy, zx, 0b1010), lanes(c.eye[0]));
        const __m256d y = _mm256_sub_pd(_mm256_shuffle_pd(xy, yz, 0b0101), lanes(c.eye[1]));
        const __m256d z = _mm256_sub_pd(_mm256_shuffle_pd(zx, yz, 0b1010), lanes(c.eye[2]));
        const __m256d depth = dot3(map_.depth, x, y, z);
        const __m256d den = c.parallel ? lanes(1.0) : depth;
        const __m256d abs = _mm256_castsi256_pd(_mm256_set1_epi64x(INT64_MAX));
        const __m256d size = _mm256_add_pd(_mm256_add_pd(_mm256_and_pd(x, abs), _mm256_and_pd(y, abs)), _mm256_and_pd(z, abs));
        const __m256d usable = c.parallel ? _mm256_castsi256_pd(_mm256_set1_epi64x(-1))
                                          : _mm256_cmp_pd(den, _mm256_mul_pd(lanes(CameraRays::PixelMap::kMinDen), size), _CMP_GT_OQ);
        const __m256d col = _mm256_div_pd(_mm256_add_pd(dot3(map_.col, x, y, z), lanes(map_.col0)), den);
        const __m256d row = _mm256_div_pd(_mm256_add_pd(dot3(map_.row, x, y, z), lanes(map_.row0)), den);
        __m128 out[4] = {_mm256_cvtpd_ps(_mm256_and_pd(col, usable)), _mm256_cvtpd_ps(_mm256_and_pd(row, usable)),
                         _mm256_cvtpd_ps(depth), _mm256_cvtpd_ps(_mm256_andnot_pd(usable, lanes(1.0)))};
        _MM_TRANSPOSE4_PS(out[0], out[1], out[2], out[3]);  // (column, row, depth, flag) per point
        for (int k = 0; k < 4; ++k) _mm_store_ps(points_ + 4 * (i + k), out[k]);
    }
#endif
#if defined(__SSE4_1__)
    /// The rectangle (c0, c1, r0, r1) and nearest depth of projected points whose
    /// (column, row, depth, flag) lie within [lo, hi], without branches (selects instead:
    /// their outcomes are close to random). Depth bounds: each point's stored depth is
    /// within 2^-24 of it relative, and its double projection within the depth slack; 2^-21
    /// and twice the slack also cover the rounding of these operations. The pixels are
    /// those whose centres lie within the margin of the points' box (the first column
    /// c0 >= lo - margin, the last c1 <= hi + margin; rows likewise), clamped to [0, n] and
    /// [-1, n - 1]; every pixel when a point has no usable projection.
    __m128 rect4(__m128 lo, __m128 hi, float& near) const {
        const float lo_z = _mm_cvtss_f32(_mm_movehl_ps(lo, lo)), hi_z = _mm_cvtss_f32(_mm_movehl_ps(hi, hi));
        const auto [lo_depth, far] = depth_bounds(lo_z, hi_z);
        near = lo_depth;
        __m128 v = pixel_span(lo, hi);
        const __m128 unknown = _mm_cmpneq_ps(_mm_shuffle_ps(hi, hi, _MM_SHUFFLE(3, 3, 3, 3)), _mm_setzero_ps());
        v = _mm_blendv_ps(v, any4_, unknown);
        // empty: c0 > c1 or r0 > r1, or every depth outside [near, far]
        const __m128 inverted = _mm_cmpgt_ps(v, _mm_shuffle_ps(v, v, _MM_SHUFFLE(2, 3, 0, 1)));
        __m128 empty = _mm_or_ps(_mm_shuffle_ps(inverted, inverted, _MM_SHUFFLE(2, 2, 0, 0)),
                                 _mm_shuffle_ps(inverted, inverted, _MM_SHUFFLE(0, 0, 2, 2)));
        empty = _mm_or_ps(empty, _mm_castsi128_ps(_mm_set1_epi32(-int((near > far_) | (far < near_)))));
        near = _mm_cvtss_f32(_mm_blendv_ps(_mm_set_ss(near), _mm_set_ss(HUGE_VALF), empty));
        return _mm_blendv_ps(v, none4_, empty);
    }
    static void store(__m128 v, ImageRect& rect) {
        _mm_storel_epi64(reinterpret_cast<__m128i*>(&rect), _mm_packus_epi32(_mm_cvtps_epi32(v), _mm_setzero_si128()));
    }
#endif

#if !defined(__SSE4_1__)
    /// As frame_triangle, for the points listed in [p, end) together.
    Reach frame_points(const uint32_t* p, const uint32_t* end, ImageRect& out) const {
        float lo[4] = {HUGE_VALF, HUGE_VALF, HUGE_VALF, HUGE_VALF}, hi[4] = {-HUGE_VALF, -HUGE_VALF, -HUGE_VALF, -HUGE_VALF};
        for (; p != end; ++p)
            for (int k = 0; k < 4; ++k) lo[k] = std::min(lo[k], (*this)[*p][k]), hi[k] = std::max(hi[k], (*this)[*p][k]);
        const auto [near, far] = depth_bounds(lo[2], hi[2]);
        out = kNoPixels;
        if (near > far_ || far < near_) return Reach::none;
        out.near = near;
        const CameraSpec& cam = rays_.spec();
        const float nx = float(cam.nx), ny = float(cam.ny);
        if (hi[3] != 0) {
            out.c0 = out.r0 = 0, out.c1 = uint16_t(nx - 1), out.r1 = uint16_t(ny - 1);
            return Reach::unknown;
        }
        const float c0 = std::min(std::max(std::ceil(lo[0] - margin_), 0.0f), nx);
        const float c1 = std::min(std::max(std::floor(hi[0] + margin_), -1.0f), nx - 1);
        const float r0 = std::min(std::max(std::ceil(lo[1] - margin_), 0.0f), ny);
        const float r1 = std::min(std::max(std::floor(hi[1] + margin_), -1.0f), ny - 1);
        if (c0 > c1 || r0 > r1) {
            out = kNoPixels;
            return Reach::none;
        }
        out.c0 = uint16_t(c0), out.c1 = uint16_t(c1), out.r0 = uint16_t(r0), out.r1 = uint16_t(r1);
        return Reach::rect;
    }
#endif

    /// Bounds {near, far} on the depths within [lo_z, hi_z] of stored point depths (see rect4).
    [[nodiscard]] std::pair<float, float> depth_bounds(float lo_z, float hi_z) const {
        return {lo_z - (std::fabs(lo_z) * 0x1p-21f + slack_), hi_z + (std::fabs(hi_z) * 0x1p-21f + slack_)};
    }

    /// How far down the leaf points' list framing asks for points ahead of its loads: the
    /// next leaves' (compare_builds, frog 1024x1024, 2 threads, two processes per build:
    /// 0.959x the time; 8, 32 and 64 ahead alike).
    static constexpr std::ptrdiff_t kAhead = 16;
    /// Whether a pixel's ray may hit a triangle whose plane holds the eye exactly. Such a
    /// ray meets it at the eye alone (the kernel's t = 0; a ray within the plane misses):
    /// only with no near distance, and only when the eye lies on the triangle (exact
    /// orientations of the eye against each edge, in a plane of two axes where the
    /// triangle has an area; a triangle with none misses every ray).
    [[nodiscard]] bool through_eye(const uint32_t tri[3]) const {
        const CameraSpec& c = rays_.spec();
        if (c.near > 0) return false;
        const double* p[3] = {scene_.point(tri[0]), scene_.point(tri[1]), scene_.point(tri[2])};
        for (int k = 0; k < 3; ++k) {
            double axis[3] = {0, 0, 0};
            axis[k] = 1;
            const int area = exact::orientation(p[1], p[2], p[0], axis);
            if (area == 0) continue;
            for (int j = 0; j < 3; ++j)
                if (exact::orientation(p[j], p[(j + 1) % 3], c.eye, axis) == -area) return false;
            return true;
        }
        return false;
    }

    /// Leaf i's rectangle: that of its points (each once), which holds each triangle's at
    /// a fraction of the work; or, when a point has no usable projection (the rectangle
    /// would be the whole image), the join of its triangles' (cone_rect for those).
    void frame_leaf(uint32_t i) {
        const CameraTree& tree = scene_.camera;
        const uint32_t *p = tree.leaf_points.data() + tree.leaf_offsets[i], *end = tree.leaf_points.data() + tree.leaf_offsets[i + 1];
#if defined(__SSE4_1__)
        __m128 lo = _mm_set1_ps(HUGE_VALF), hi = _mm_set1_ps(-HUGE_VALF);
        const uint32_t* list_end = tree.leaf_points.data() + tree.leaf_points.size();
        for (; p != end; ++p) {
            if (list_end - p > kAhead) prefetch_line(points_ + 4 * std::size_t(p[kAhead]));  // (the next leaves' points)
            const __m128 v = _mm_load_ps((*this)[*p]);
            lo = _mm_min_ps(lo, v);
            hi = _mm_max_ps(hi, v);
        }
        store(rect4(lo, hi, node_[i].rect.near), node_[i].rect);
        const bool unknown = _mm_cvtss_f32(_mm_shuffle_ps(hi, hi, 3)) != 0 && !node_[i].rect.empty();
#else
        const bool unknown = frame_points(p, end, node_[i].rect) == Reach::unknown;
#endif
        if (!unknown) return;
        ImageRect joined = kNoPixels;
        for (uint32_t t = node_[i].index, last = t + node_[i].count; t < last; ++t) {
            ImageRect rect;
            if (frame_triangle(scene_.triangles.data() + 3 * std::size_t(t), rect) != Reach::none) joined.join(rect);
        }
        node_[i].rect = joined;
    }

    /// Inner node i's rectangle: the join of its children's.
    void join_children(uint32_t i) {
        const ProjectedNode* child = node_ + node_[i].index;
#if defined(__SSE4_1__)
        // both children in two loads: min c0, r0 and max c1, r1 (16-bit lanes), min near
        // (float lane 2), the node's own links (lane 3)
        const __m128i a = _mm_loadu_si128(reinterpret_cast<const __m128i*>(child));
        const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(child + 1));
        const __m128 pixels = _mm_castsi128_ps(_mm_blend_epi16(_mm_min_epu16(a, b), _mm_max_epu16(a, b), 0b1010));
        __m128 joined = _mm_blend_ps(pixels, _mm_min_ps(_mm_castsi128_ps(a), _mm_castsi128_ps(b)), 0b0100);
        joined = _mm_blend_ps(joined, _mm_loadu_ps(reinterpret_cast<const float*>(node_ + i)), 0b1000);
        _mm_storeu_ps(reinterpret_cast<float*>(node_ + i), joined);
#else
        node_[i].rect = child[0].rect;
        node_[i].rect.join(child[1].rect);
#endif
    }

    const Scene& scene_;
    const CameraRays& rays_;
    CameraRays::PixelMap map_;
    ScratchPool::Block memory_;  // holds points_ and node_
    float* points_;
    ProjectedNode* node_;
    double depth_slack_;
    float margin_, slack_, near_, far_;  // in single precision: see the constructor
    float sure_near_, sure_far_, sure_margin_;  // see SureHits
    std::atomic<std::size_t> next_subtree_{0};
    std::unique_ptr<std::atomic<bool>[]> projected_;  // per subtree, whether its points are projected
    static constexpr std::size_t kRun = 1 << 14;  // points a worker projects at a time (a multiple of 4)
    std::atomic<std::size_t> next_run_{0};
#if defined(__SSE4_1__)
    __m128 margin4_, floor4_, ceil4_, any4_, none4_;  // per lane of (c0, c1, r0, r1)
#endif
};

}  // namespace vrc
