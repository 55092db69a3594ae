// Rays from one point in a grid: a lidar's rings x azimuth steps, a panorama's rows x
// columns, a camera of the caller's own (Scene.intersect with one origin and a 2-D batch
// of directions). Neighbouring rays of such a sweep meet the same nodes, so a tile of them
// goes through the wide BVH as one bundle. Each ray is projected once onto the plane at
// distance 1 along the tile's middle direction; a node's children are projected there too
// and kept only where a block of rays meets them before those rays' closest hits, so a
// node is tested once for all its rays; a leaf is tested only on the rays inside its
// projection. The test is the per-ray one (test_triangle) with the exact watertight
// kernel, so every answer is trace_ray's. Frustum culling of ray packets follows
// Reshetov, Soupikov and Hurley, "Multi-level ray tracing algorithm" (SIGGRAPH 2005).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <optional>
#include <vector>

#include "camera_rays.hpp"
#include "cost_chooser.hpp"
#include "kernel_watertight.hpp"
#include "traverse.hpp"
#include "triangle_filter.hpp"
#include "traverse_wide.hpp"

namespace vrc {

/// Rays from one origin with directions from an array, ray k = column + row * cols: row
/// r, column c of a rows x cols grid whose neighbours point in neighbouring directions
/// (a tile where they do not goes ray by ray).
class SweepRays {
   public:
    SweepRays(const double* origin, const double* directions, int64_t rows, int64_t cols, double tmin, double tmax)
        : rays_(origin, directions, std::size_t(rows * cols), tmin, tmax, true), o_(origin), d_(directions), rows_(rows),
          cols_(cols) {
        // Tiles about as wide as tall in angle: a lidar's rings lie farther apart than its
        // azimuth steps.
        const double across_row = turn(rows / 2, cols / 2, 0, 1), across_column = turn(rows / 2, cols / 2, 1, 0);
        int64_t tile_rows = 1;
        while (tile_rows < kTileRays && tile_rows * tile_rows * across_column < kTileRays * across_row) tile_rows *= 2;
        tile_rows_ = std::min(tile_rows, rows);
        tile_cols_ = std::min(kTileRays / tile_rows, cols);
    }
    [[nodiscard]] std::size_t size() const { return std::size_t(rows_ * cols_); }
    [[nodiscard]] Ray ray(std::size_t k) const { return rays_.ray(k); }
    [[nodiscard]] const double* origin() const { return o_; }
    [[nodiscard]] int64_t cols() const { return cols_; }

    /// A tile's rows r0..r1 and columns c0..c1 (inclusive).
    struct TileRays {
        int64_t r0, r1, c0, c1;
    };
    /// Rays per tile: enough that a node tested for a bundle serves many rays, few enough
    /// that the bundle's rectangles stay tight (512 was the fastest of 128 to 1,024 for the
    /// benchmark's lidar over the frog and the terrain).
    static constexpr int64_t kTileRays = 512;
    [[nodiscard]] std::size_t n_tiles() const { return std::size_t(tiles_x() * n_tile_rows()); }
    /// Tiles side by side (a lidar's: the same rings, neighbouring azimuths) form a row.
    [[nodiscard]] int64_t n_tile_rows() const { return (rows_ + tile_rows_ - 1) / tile_rows_; }
    [[nodiscard]] int64_t tile_row(std::size_t tile) const { return int64_t(tile) / tiles_x(); }
    [[nodiscard]] TileRays tile_rays(std::size_t tile) const {
        const int64_t c0 = int64_t(tile) % tiles_x() * tile_cols_, r0 = int64_t(tile) / tiles_x() * tile_rows_;
        return {r0, std::min(r0 + tile_rows_, rows_) - 1, c0, std::min(c0 + tile_cols_, cols_) - 1};
    }
    template <class F>
    void for_each_in_tile(std::size_t tile, F&& f) const {
        const TileRays t = tile_rays(tile);
        for (int64_t r = t.r0; r <= t.r1; ++r)
            for (int64_t c = t.c0; c <= t.c1; ++c) f(std::size_t(c + r * cols_));
    }
    [[nodiscard]] bool tile_may_hit(std::size_t) const { return true; }

   private:
    [[nodiscard]] int64_t tiles_x() const { return (cols_ + tile_cols_ - 1) / tile_cols_; }
    /// The angle (about) between the unit directions of ray (r, c) and ray (r + dr, c + dc).
    [[nodiscard]] double turn(int64_t r, int64_t c, int64_t dr, int64_t dc) const {
        if (r + dr >= rows_ || c + dc >= cols_) return HUGE_VAL;
        const double* a = d_ + 3 * (c + r * cols_);
        const double* b = d_ + 3 * (c + dc + (r + dr) * cols_);
        const double la = std::sqrt(dot(a, a)), lb = std::sqrt(dot(b, b));
        double s = 0;
        for (int k = 0; k < 3; ++k) s += std::fabs(a[k] / la - b[k] / lb);
        return s;
    }
    ArrayRays rays_;
    const double *o_, *d_;
    int64_t rows_, cols_, tile_rows_ = 1, tile_cols_ = 1;
};

/// Traces tiles of a sweep as bundles (see the top of this file). One per worker.
template <template <class> class KernelT, class Real>
class BundleTracer {
    using Kernel = KernelT<Real>;
    static constexpr int kMaxRays = int(SweepRays::kTileRays);
    static constexpr int kBlock = 8;  ///< rays of a row tested against a triangle's rectangle together
    struct Rect {
        double a0 = HUGE_VAL, a1 = -HUGE_VAL, b0 = HUGE_VAL, b1 = -HUGE_VAL;
        void grow(double a, double b) {
            a0 = std::min(a0, a), a1 = std::max(a1, a);
            b0 = std::min(b0, b), b1 = std::max(b1, b);
        }
        [[nodiscard]] double area() const { return (a1 - a0) * (b1 - b0); }
        [[nodiscard]] bool meets(const Rect& o) const { return a0 <= o.a1 && o.a0 <= a1 && b0 <= o.b1 && o.b0 <= b1; }
    };
    /// A node's lanes projected (project): their rectangles' sides and least distances.
    struct ProjectedLanes {
        alignas(32) double a0[WideNode::kWidth], a1[WideNode::kWidth], b0[WideNode::kWidth], b1[WideNode::kWidth];
        alignas(32) double nearest[WideNode::kWidth];
    };

   public:
    BundleTracer(const Scene& scene, const SweepRays& rays, const CastContext& context)
        : scene_(scene), rays_(rays), context_(context), history_(std::size_t(rays.n_tile_rows())) {
        for (int k = 0; k < 3; ++k) origin_[k] = rays.origin()[k] - scene.anchor[k];
        for (int k = 0; k < 3; ++k)
            reach_ = std::max({reach_, std::fabs(double(scene.bounds.lo[k])), std::fabs(double(scene.bounds.hi[k]))});
        reach_ += std::max({std::fabs(origin_[0]), std::fabs(origin_[1]), std::fabs(origin_[2])});
    }
    BundleTracer(const BundleTracer&) = delete;  // (kernels point into ray_)

    /// Traces tile `tile` and writes each ray's closest hit with store(k, ray, hit).
    template <class Store>
    void trace(std::size_t tile, const Store& store) {
        const SweepRays::TileRays t = rays_.tile_rays(tile);
        rows_ = int(t.r1 - t.r0 + 1), cols_ = int(t.c1 - t.c0 + 1), n_ = rows_ * cols_;
        for (int r = 0, j = 0; r < rows_; ++r) {  // (row by row: no division per ray)
            const std::size_t row_start = std::size_t(t.c0 + (t.r0 + r) * rays_.cols());
            for (int c = 0; c < cols_; ++c, ++j) {
                index_[j] = row_start + std::size_t(c);
                ray_[j] = rays_.ray(index_[j]);
                hit_[j] = Hit<Real>{};
                bound_[j] = ray_[j].tmax;
            }
        }
        if (scene_.wide.empty() || !may_meet_scene()) return store_tile(store);
        // A bundle too wide to project, incoherent, or costlier than its rays (see
        // traverse and RowHistory): ray by ray.
        RowHistory& history = history_[std::size_t(rays_.tile_row(tile))];
        CostChooser& ways = history.bundles;
        bool bundle = ways.pick();
        // A look at ray by ray while bundles lead: the bundle's first rows traced again,
        // timed per ray (the same answers), instead of the whole tile at 2x to 3x its
        // bundle's time.
        const bool look = !bundle && ways.leading();
        bundle |= look;
        const auto start = std::chrono::steady_clock::now();
        if (bundle && enclose() && traverse(history.visit_budget() * n_)) {
            ways.record(true, seconds_since(start) / n_);
            if (look) {
                const int sampled = (n_ + kSampleShare - 1) / kSampleShare;
                const auto again = std::chrono::steady_clock::now();
                trace_by_ray(history, sampled);
                ways.record(false, seconds_since(again) / sampled);
            }
        } else {  // (a bundle cut short costs its visits and its rays: both are known)
            const auto by_ray = std::chrono::steady_clock::now();
            trace_by_ray(history, n_);
            ways.record(false, seconds_since(by_ray) / n_);
            if (bundle) ways.record(true, seconds_since(start) / n_);
        }
        store_tile(store);
    }

   private:
    /// What a worker has seen of a row of tiles: neighbouring tiles of a sweep cost alike
    /// (a lidar's rings meet a height field at the same range all around), so the row's
    /// tiles go as bundles or ray by ray, whichever the worker measures cheaper per ray
    /// there (the other tried again every 64th tile; while bundles lead, ray by ray is
    /// timed on a bundle's first rows: a frog's tile takes 2x to 3x its bundle's time ray
    /// by ray), and the nodes the row's rays tested bound what a bundle may
    /// spend before it is cut and its rays go one by one. A bundle's visit of a node or
    /// leaf costs about as much as ten node tests of a single ray (1,100 cycles against 90
    /// to 170, rdtsc on the frog's and the terrain's scans): on the frog, whose rays test
    /// 20 to 30 nodes, bundles of up to 2 visits per ray took 0.3x to 0.5x the time of
    /// their rays traced one by one; on the terrain, whose rays test 2.5 to 11, the steep
    /// rings' bundles, cut or not, took 1.1x the time of their rays.
    struct RowHistory {
        static constexpr double kNodesPerVisit = 10;
        double nodes_per_ray = -1;      // of the row's last tile traced ray by ray (-1: none yet)
        CostChooser bundles{true, 64};  // the row's tiles as bundles (tried first), or ray by ray
        [[nodiscard]] double visit_budget() const {
            return nodes_per_ray < 0 ? kVisitsPerRay : std::clamp(nodes_per_ray / kNodesPerVisit, 0.25, double(kVisitsPerRay));
        }
    };

    /// Whether some ray of the tile may meet the scene's box: not when, on some axis, the
    /// origin lies beyond the box and each ray points away from it or along it (the rings
    /// of a lidar above a height field that look up: they made the bundle's projection,
    /// and before that every array's miss, for nothing). The origin must be beyond the
    /// box by more than its rounding relative to the anchor.
    [[nodiscard]] bool may_meet_scene() const {
        unsigned away[2] = {0, 0};  // axes with the origin above (below) the box
        for (int k = 0; k < 3; ++k) {
            const double margin = 0x1p-50 * (std::fabs(origin_[k]) + reach_);
            away[0] |= unsigned(origin_[k] > double(scene_.bounds.hi[k]) + margin) << k;
            away[1] |= unsigned(origin_[k] < double(scene_.bounds.lo[k]) - margin) << k;
        }
        if (!(away[0] | away[1])) return true;
        for (int j = 0; j < n_; ++j) {
            const double* d = ray_[j].dir;
            unsigned leaving = 0;
            for (int k = 0; k < 3; ++k) leaving |= unsigned(((away[0] >> k & 1) && d[k] >= 0) || ((away[1] >> k & 1) && d[k] <= 0));
            if (!leaving) return true;
        }
        return false;
    }

    /// Traces the tile's first `n` rays one by one: one after another, or several in
    /// flight where the scene is larger than the caches (the terrain's grazing rings wait
    /// for memory at every node one after another; the frog's, which find it in the
    /// caches, lose little in flight).
    void trace_by_ray(RowHistory& history, int n) {
        unsigned nodes = 0;
        if (scene_.ray_bytes() < kInterleavedBytes) {
            for (int j = 0; j < n; ++j) hit_[j] = trace_ray<KernelT, Real>(scene_, ray_[j], context_, NoSink{}, &nodes);
        } else {
            which_.resize(std::size_t(n));
            std::iota(which_.begin(), which_.end(), std::size_t(0));
            const auto take = [&](std::size_t j, const Ray&, const Hit<Real>& hit, NoSink*) { hit_[j] = hit; };
            in_flight_.run(nodes, [&](int searches) {
                trace_rays_interleaved<KernelT, Real, HitPolicy::closest>(scene_, TileRays{ray_}, which_, context_, take,
                                                                          static_cast<NoSink*>(nullptr), &nodes, searches);
            });
        }
        history.nodes_per_ray = double(nodes) / n;
    }
    /// The part of a tile a look at ray by ray traces (trace): its first rows.
    static constexpr int kSampleShare = 8;
    static double seconds_since(std::chrono::steady_clock::time_point start) {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }

    /// The tile's rays by their place in it, as trace_rays_interleaved asks for them.
    struct TileRays {
        const Ray* rays;
        [[nodiscard]] Ray ray(std::size_t j) const { return rays[j]; }
    };

    /// Stores the tile's hits and misses. The rows of the mesh's point arrays the hits
    /// interpolate lie scattered in the mesh's point order: they are asked for all at once
    /// first, so that their loads overlap (stored one by one, each hit waited on its own).
    template <class Store>
    void store_tile(const Store& store) {
        int n_hits = 0;
        for (int j = 0; j < n_; ++j)
            if (hit_[j].found()) store.prefetch(hit_prims_[n_hits++] = hit_[j].prim);
        store.prefetch_rows(hit_prims_, std::size_t(n_hits));
        for (int r = 0; r < rows_; ++r) {  // hits one by one, runs of misses at once
            for (int j = r * cols_, end = (r + 1) * cols_; j < end;) {
                if (hit_[j].found()) {
                    store(index_[j], ray_[j], hit_[j]);
                    ++j;
                    continue;
                }
                const int run = j;
                while (j < end && !hit_[j].found()) ++j;
                store.misses(index_[run], std::size_t(j - run));
            }
        }
    }

    /// Finds the bundle's axis c, its cross axes p, q and each ray's projection (a, b) =
    /// (d.p, d.q) / d.c onto the plane at distance 1 along c, with the rectangles of the
    /// bundle and its blocks, and the blocks' far bounds. False when some ray turns too far
    /// from c for the projection (beyond about 80 degrees), or the rays are not a coherent
    /// grid.
    bool enclose() {
        const double* mid = ray_[n_ / 2].dir;
        const double* last = ray_[(n_ / 2 / cols_) * cols_ + cols_ - 1].dir;  // the middle row's last ray
        const double* first = ray_[(n_ / 2 / cols_) * cols_].dir;
        const double lm = std::sqrt(dot(mid, mid));
        for (int k = 0; k < 3; ++k) c_[k] = mid[k] / lm;
        double along[3] = {last[0] - first[0], last[1] - first[1], last[2] - first[2]};
        if (cols_ == 1) along[0] = c_[1], along[1] = -c_[2], along[2] = c_[0];  // any direction not c
        if (!orthonormal(along, c_, p_)) {
            const double other[3] = {c_[1] + c_[2], c_[2] - c_[0], -c_[0] - c_[1]};
            if (!orthonormal(other, c_, p_)) return false;
        }
        cross(c_, p_, q_);
        all_ = Rect{};
        for (int r = 0; r < rows_; ++r) {
            for (int j = r * cols_; j < (r + 1) * cols_; ++j) {
                const double* d = ray_[j].dir;
                const double w = w_[j] = dot(d, c_);
                if (!(w > 0 && w * w > 0.03 * dot(d, d))) return false;
                const double inverse = 1 / w;
                a_[j] = dot(d, p_) * inverse, b_[j] = dot(d, q_) * inverse;
                const int column = j - r * cols_, b = r * blocks_per_row() + column / kBlock;
                if (column % kBlock == 0) blocks_[b] = Rect{}, block_first_[b] = j;
                block_of_[j] = b;
                blocks_[b].grow(a_[j], b_[j]);
                all_.grow(a_[j], b_[j]);
            }
        }
        // Rays in neighbouring directions cover the tile's rectangle with their blocks'
        // small ones; blocks each spanning much of it (a grid of unrelated directions) would
        // send every node to every block: such a tile goes ray by ray.
        n_blocks_ = rows_ * blocks_per_row();
        block_first_[n_blocks_] = n_;
        double blocks_area = 0;
        for (int b = 0; b < n_blocks_; ++b) blocks_area += blocks_[b].area();
        if (blocks_area > 2 * all_.area()) return false;
        const double* axis[3] = {c_, p_, q_};
        for (int i = 0; i < 3; ++i) axes_[i].set(axis[i], origin_, reach_);
        for (int b = 0; b < n_blocks_; ++b) {
            block_far_[b] = search_far(b);
            block_a0_[b] = blocks_[b].a0, block_a1_[b] = blocks_[b].a1, block_b0_[b] = blocks_[b].b0, block_b1_[b] = blocks_[b].b1;
        }
        for (int b = n_blocks_; b < n_blocks_ + 3; ++b) block_a0_[b] = HUGE_VAL;  // (meets nothing)
        set_far();
        return true;
    }

    /// Unit vector u along v's part orthogonal to the unit vector c; false when none.
    static bool orthonormal(const double v[3], const double c[3], double u[3]) {
        const double along = dot(v, c);
        for (int k = 0; k < 3; ++k) u[k] = v[k] - along * c[k];
        const double l = std::sqrt(dot(u, u));
        if (!(l > 1e-6 * std::sqrt(dot(v, v)))) return false;
        for (int k = 0; k < 3; ++k) u[k] /= l;
        return true;
    }
    [[nodiscard]] int blocks_per_row() const { return (cols_ + kBlock - 1) / kBlock; }

    /// An axis n (c, p or q) on eight boxes at once in float: n.x at each box's corners
    /// least and most along n. Relative to the origin, n.(x - o), they are bounded by
    /// those minus n.o and `slack`, which covers the float roundings (of n, the products
    /// and sums, for boxes within `reach` of the anchor).
    struct LaneAxis {
        Lane8 n[3];
        int least_row[3], most_row[3];  // the bounds rows of those corners: lo (0..2) or hi (3..5)
        double n_o = 0, slack = 0;
        void set(const double axis[3], const double origin[3], double reach) {
            n_o = 0;
            double size = 0;
            for (int k = 0; k < 3; ++k) {
                n[k] = lanes_set(static_cast<float>(axis[k]));
                least_row[k] = axis[k] >= 0 ? k : 3 + k;
                most_row[k] = axis[k] >= 0 ? 3 + k : k;
                n_o += axis[k] * origin[k];
                size += std::fabs(axis[k]);
            }
            slack = 1e-6 * size * reach;
        }
        [[gnu::always_inline]] Lane8 at(const WideNode& node, const int row[3]) const {
            return lanes_add(lanes_add(lanes_mul(n[0], lanes_load(node.bounds[row[0]])),
                                       lanes_mul(n[1], lanes_load(node.bounds[row[1]]))),
                             lanes_mul(n[2], lanes_load(node.bounds[row[2]])));
        }
        /// Bounds of n.(x - o) over the box whose least and most n.x are given.
        [[nodiscard]] double low(float least) const { return double(least) - n_o - slack; }
        [[nodiscard]] double high(float most) const { return double(most) - n_o + slack; }
    };

    /// Block b's far bound: the greatest distance along c its rays still search to.
    [[nodiscard]] double search_far(int b) const {
        double far = 0;
        for (int j = block_first_[b]; j < block_first_[b + 1]; ++j) far = std::max(far, bound_[j] * w_[j]);
        return far * (1 + 1e-9);  // (above the rounding of the product)
    }
    /// The bundle's far bound, the greatest of its blocks', and its float limit on boxes.
    void set_far() {
        far_ = *std::max_element(block_far_, block_far_ + n_blocks_);
        far_limit_ = std::isinf(far_) ? HUGE_VALF : round_up(far_ + axes_[0].n_o + axes_[0].slack);
    }
    /// Ray j came closer: its block's far bound is to be found again (update_blocks).
    void came_closer(int j) {
        const int b = block_of_[j];
        if (!block_changed_[b]) block_changed_[b] = true, changed_blocks_[n_changed_++] = b;
    }
    /// After rays of a leaf came closer: their blocks' far bounds, each once, then the
    /// bundle's, when one of those blocks held it (bounds only shrink).
    void update_blocks() {
        bool held = false;
        for (int i = 0; i < n_changed_; ++i) {
            const int b = changed_blocks_[i];
            block_changed_[b] = false;
            held |= block_far_[b] >= far_;
            block_far_[b] = search_far(b);
        }
        n_changed_ = 0;
        if (held) set_far();
    }

    /// Blocks `first` to `first + 3` whose rays may meet a box projecting into `rect` at
    /// distances along c from `nearest` on, as bits.
    [[nodiscard]] unsigned blocks_meeting(int first, const Rect& rect, double nearest) const {
        Double4 a0, a1, b0, b1, far;
        std::memcpy(&a0, block_a0_ + first, sizeof a0), std::memcpy(&a1, block_a1_ + first, sizeof a1);
        std::memcpy(&b0, block_b0_ + first, sizeof b0), std::memcpy(&b1, block_b1_ + first, sizeof b1);
        std::memcpy(&far, block_far_ + first, sizeof far);
        return lane_bits((a0 <= rect.a1) & (a1 >= rect.a0) & (b0 <= rect.b1) & (b1 >= rect.b0) & (far >= nearest));
    }
    /// Whether some block's rays may meet such a box.
    [[nodiscard]] bool any_block_meets(const Rect& rect, double nearest) const {
        if (!rect.meets(all_)) return false;
        for (int b = 0; b < n_blocks_; b += 4)
            if (blocks_meeting(b, rect, nearest)) return true;
        return false;
    }

    /// The projections of box lanes `first` to `first + 3` (their least and most along c,
    /// p, q in `extent`) onto the plane w = 1, as rectangles' sides, and their least
    /// distances w along c; as bits, the lanes whose rectangle meets the bundle's. The rays
    /// meet only points with w >= 0: a box wholly behind meets nothing; one reaching across
    /// w = 0 bounds a = u / w only on the sides where u keeps its sign.
    unsigned project(const float extent[6][WideNode::kWidth], int first, ProjectedLanes& out) const {
        const auto side = [&](int row, const LaneAxis& axis, double shift) {
            Double4 x;
            for (int k = 0; k < 4; ++k) x[k] = double(extent[row][first + k]);
            return x - axis.n_o + shift;
        };
        const Double4 w0 = side(0, axes_[0], -axes_[0].slack), w1 = side(1, axes_[0], axes_[0].slack);
        const Double4 u0 = side(2, axes_[1], -axes_[1].slack), u1 = side(3, axes_[1], axes_[1].slack);
        const Double4 v0 = side(4, axes_[2], -axes_[2].slack), v1 = side(5, axes_[2], axes_[2].slack);
        // u / w over the box lies between these quotients; 1e-12 covers their rounding
        // (two, with the reciprocals: relative 2^-52, where the rays' projections lie, below 9).
        const double s = 1e-12;
        const Double4 r0 = 1 / w0, r1 = 1 / w1, inf = Double4{} + HUGE_VAL;
        const auto least = [](Double4 x, Double4 y) { return x < y ? x : y; };
        const auto most = [](Double4 x, Double4 y) { return x > y ? x : y; };
        const Mask4 front = w0 > 0;  // (elsewhere r0 is not used)
        const Double4 a0 = front ? least(u0 * r0, u0 * r1) - s : (u0 > 0 ? u0 * r1 - s : -inf);
        const Double4 a1 = front ? most(u1 * r0, u1 * r1) + s : (u1 < 0 ? u1 * r1 + s : inf);
        const Double4 b0 = front ? least(v0 * r0, v0 * r1) - s : (v0 > 0 ? v0 * r1 - s : -inf);
        const Double4 b1 = front ? most(v1 * r0, v1 * r1) + s : (v1 < 0 ? v1 * r1 + s : inf);
        std::memcpy(out.a0 + first, &a0, sizeof a0), std::memcpy(out.a1 + first, &a1, sizeof a1);
        std::memcpy(out.b0 + first, &b0, sizeof b0), std::memcpy(out.b1 + first, &b1, sizeof b1);
        std::memcpy(out.nearest + first, &w0, sizeof w0);
        return lane_bits((w1 >= 0) & (a0 <= all_.a1) & (a1 >= all_.a0) & (b0 <= all_.b1) & (b1 >= all_.b0)) << first;
    }

    /// False, with the tile unfinished, once it has taken more than `budget` nodes and
    /// leaves (at most kVisitsPerRay for each of its rays): rays far apart (a coarse sweep:
    /// 64 azimuth steps put 90 degrees in one tile) or grazing a height field reach nodes
    /// none of them enters, and ray by ray costs less than such a bundle.
    static constexpr int kVisitsPerRay = 4;
    bool traverse(double budget) {
        for (int j = 0; j < n_; ++j) kernel_[j].reset(), filter_[j].reset();
        int visits = 0;
        struct Pending {
            uint32_t child, count;
            float near;
            double nearest;  // (a leaf's: its least distance along c, and its projection)
            Rect rect;
        };
        Pending stack[WideNode::kWidth * 128];
        int top = 0;
        stack[top++] = {0, 0, -HUGE_VALF, 0, Rect{}};
        while (top > 0) {
            const Pending e = stack[--top];
            if (e.near > far_limit_) continue;
            if (++visits > budget) return false;
            if (e.count) {
                leaf(e.child, leaf_size(e.count), e.rect, e.nearest);
                continue;
            }
            const WideNode& node = scene_.wide[e.child];
            alignas(32) float extent[6][WideNode::kWidth];
            const Lane8 near = axes_[0].at(node, axes_[0].least_row);
            unsigned mask = lanes_le(lanes_load(node.bounds[0]), lanes_load(node.bounds[3]));  // (empty lanes)
            mask &= lanes_le(near, lanes_set(far_limit_));
            if (!mask) continue;
            lanes_store(extent[0], near);
            lanes_store(extent[1], axes_[0].at(node, axes_[0].most_row));
            for (int i = 1; i < 3; ++i) {
                lanes_store(extent[2 * i], axes_[i].at(node, axes_[i].least_row));
                lanes_store(extent[2 * i + 1], axes_[i].at(node, axes_[i].most_row));
            }
            int order[WideNode::kWidth], n = 0;
            ProjectedLanes lanes;
            mask &= project(extent, 0, lanes) | project(extent, 4, lanes);
            Rect rects[WideNode::kWidth];
            for (; mask; mask &= mask - 1) {  // farthest first, so the nearest is popped first
                const int c = __builtin_ctz(mask);
                rects[c] = Rect{lanes.a0[c], lanes.a1[c], lanes.b0[c], lanes.b1[c]};
                if (!any_block_meets(rects[c], lanes.nearest[c])) continue;
                int at = n++;
                for (; at > 0 && extent[0][order[at - 1]] < extent[0][c]; --at) order[at] = order[at - 1];
                order[at] = c;
            }
            for (int i = 0; i < n; ++i) {
                const int c = order[i];
                if (node.count[c] == 0)
                    prefetch_range(&scene_.wide[node.child[c]], sizeof(WideNode));
                else  // a leaf's block (its point indices and points follow when it is popped)
                    prefetch_range(&scene_.leaf(node.child[c]), LeafBlock::bytes(leaf_size(node.count[c])));
                stack[top++] = {node.child[c], node.count[c], extent[0][c], lanes.nearest[c], rects[c]};
            }
        }
        return true;
    }

    /// Tests the `count` triangles of leaf `index` on the rays that may meet its box
    /// (projecting into `rect`, from `nearest` along c on).
    void leaf(uint32_t index, uint32_t count, const Rect& rect, double nearest) {
        int n = 0;  // the rays to test (then the points are asked for: many leaves have none)
        const Double4 a0 = Double4{} + rect.a0, a1 = Double4{} + rect.a1, b0 = Double4{} + rect.b0,
                      b1 = Double4{} + rect.b1, near = Double4{} + nearest;
        for (int first = 0; first < n_blocks_; first += 4) {
            for (unsigned meeting = blocks_meeting(first, rect, nearest); meeting; meeting &= meeting - 1) {
                // the block's rays (at most kBlock, in a row) four at a time
                const int b = first + __builtin_ctz(meeting), first_ray = block_first_[b];
                unsigned in = 0;
                for (int h = 0; h < kBlock; h += 4) {
                    Double4 a, bb, bound, w;
                    std::memcpy(&a, a_ + first_ray + h, sizeof a);
                    std::memcpy(&bb, b_ + first_ray + h, sizeof bb);
                    std::memcpy(&bound, bound_ + first_ray + h, sizeof bound);
                    std::memcpy(&w, w_ + first_ray + h, sizeof w);
                    in |= lane_bits((a >= a0) & (a <= a1) & (bb >= b0) & (bb <= b1) & (bound * w >= near)) << h;
                }
                for (in &= (1u << (block_first_[b + 1] - first_ray)) - 1; in; in &= in - 1) {
                    const int j = first_ray + __builtin_ctz(in);
                    candidate_a_[n] = a_[j], candidate_b_[n] = b_[j], candidates_[n++] = j;
                }
            }
        }
        if (n == 0) return;
        for (int c = n; c < n + 3; ++c) candidate_a_[c] = candidate_b_[c] = NAN;  // (outside every rectangle)
        const uint32_t first = scene_.leaf(index).first;
        for (uint32_t i = first; i < first + count; ++i) scene_.prefetch_points(i);
        if (n > kRaysByTriangle)
            by_triangle(first, count, n);
        else
            by_ray(index, first, count, n);
        update_blocks();
    }

    /// A triangle's projection (its points' (a, b), all in front): a ray whose projection
    /// lies outside it by more than the roundings of the projections misses the triangle,
    /// whose exact test would only confirm it.
    struct Outline {
        double a[3], b[3];
        double sense = 0;  ///< +1 or -1 as the outline turns, 0 when too thin to tell (or unset)
        /// Edge u as a linear function of a projection, ea a + eb b + ec, the turn's sign
        /// folded in (>= 0 inside), and how far below 0 it may fall for a projection inside.
        double ea[3], eb[3], ec[3], margin[3];
        /// Sets sense, and the edges for projections within `rect`.
        void orient(const Rect& rect) {
            const double area = (a[1] - a[0]) * (b[2] - b[0]) - (b[1] - b[0]) * (a[2] - a[0]);
            const double span = std::fabs(a[1] - a[0]) + std::fabs(b[1] - b[0]) + std::fabs(a[2] - a[0]) + std::fabs(b[2] - b[0]);
            sense = std::fabs(area) > 1e-9 * span * span ? (area > 0 ? 1 : -1) : 0;
            const double pa = std::max(std::fabs(rect.a0), std::fabs(rect.a1)), pb = std::max(std::fabs(rect.b0), std::fabs(rect.b1));
            for (int u = 0; u < 3; ++u) {
                const int v = u == 2 ? 0 : u + 1;
                const double da = a[v] - a[u], db = b[v] - b[u];
                ea[u] = -sense * db, eb[u] = sense * da, ec[u] = sense * (db * a[u] - da * b[u]);
                // The edge function is da (pb - b_u) - db (pa - a_u), |pa - a_u| <= qa and
                // |pb - b_u| <= qb within the rectangle: the projections are good to about
                // 1e-14 (values below 9), and the expanded form rounds by less than 1e-15
                // of its terms' sizes.
                const double qa = std::max(std::fabs(rect.a0 - a[u]), std::fabs(rect.a1 - a[u]));
                const double qb = std::max(std::fabs(rect.b0 - b[u]), std::fabs(rect.b1 - b[u]));
                margin[u] = 1e-9 * (std::fabs(da) * qb + std::fabs(db) * qa) + 1e-12 * (std::fabs(da) + std::fabs(db) + qa + qb) +
                            1e-15 * (std::fabs(db) * (pa + std::fabs(a[u])) + std::fabs(da) * (pb + std::fabs(b[u])));
            }
        }
        /// Lanes of the projections (pa, pb), all within the rectangle given to orient,
        /// that lie outside, four at a time.
        [[nodiscard]] Mask4 outside(Double4 pa, Double4 pb) const {
            Mask4 out = Mask4{};
            if (sense == 0) return out;
            for (int u = 0; u < 3; ++u) out |= ea[u] * pa + eb[u] * pb + ec[u] < -margin[u];
            return out;
        }
    };

    /// Many rays in a leaf's box: each triangle is projected and tested on the candidates
    /// in its own rectangle (the kernel alone: a hit needs its exact test anyway).
    static constexpr int kRaysByTriangle = 4;
    void by_triangle(uint32_t first, uint32_t count, int n) {
        for (uint32_t i = first; i < first + count; ++i) {
            const uint32_t* tri = scene_.triangles.data() + 3 * std::size_t(i);
            Rect rect;
            Outline outline;
            double nearest = HUGE_VAL;
            bool projects = true, behind = true;
            for (int v = 0; v < 3; ++v) {
                const double* point = scene_.point(tri[v]);
                const double x[3] = {point[0] - rays_.origin()[0], point[1] - rays_.origin()[1], point[2] - rays_.origin()[2]};
                const double w = dot(x, c_), size = std::fabs(x[0]) + std::fabs(x[1]) + std::fabs(x[2]);
                nearest = std::min(nearest, w);
                behind &= w < -1e-9 * size;
                if (!(w > 0.125 * size)) {
                    projects = false;
                    continue;
                }
                const double inverse = 1 / w;
                outline.a[v] = dot(x, p_) * inverse, outline.b[v] = dot(x, q_) * inverse;
                rect.grow(outline.a[v], outline.b[v]);
            }
            if (behind) continue;  // (the rays meet points with w >= 0 only)
            if (projects) {
                // A hit point projects into the triangle's projection; the projections carry
                // a few roundings of values below 9, and the hit's w is at least the least
                // vertex's.
                const double s = 1e-12;
                rect.a0 -= s, rect.a1 += s, rect.b0 -= s, rect.b1 += s;
                nearest *= 1 - 1e-9;
                outline.orient(rect);
            } else {
                rect = Rect{-HUGE_VAL, HUGE_VAL, -HUGE_VAL, HUGE_VAL};
                nearest = -HUGE_VAL;
            }
            // The candidates inside the outline, 64 at a time, four by four without a branch
            // (whether four rays meet a triangle follows no pattern the predictor learns).
            for (int base = 0; base < n; base += 64) {
                uint64_t inside = 0;
                for (int c0 = base, end = std::min(n, base + 64); c0 < end; c0 += 4) {
                    Double4 a, b;
                    std::memcpy(&a, candidate_a_ + c0, sizeof a);
                    std::memcpy(&b, candidate_b_ + c0, sizeof b);
                    const Mask4 in = (a >= rect.a0) & (a <= rect.a1) & (b >= rect.b0) & (b <= rect.b1) & ~outline.outside(a, b);
                    inside |= uint64_t(lane_bits(in)) << (c0 - base);
                }
                for (; inside; inside &= inside - 1) {
                    const int j = candidates_[base + __builtin_ctzll(inside)];
                    if (bound_[j] * w_[j] < nearest) continue;
                    const double before = bound_[j];
                    test_triangle(kernel(j), scene_, i, ray_[j].tmin, bound_[j], hit_[j]);
                    if (bound_[j] != before) came_closer(j);
                }
            }
        }
    }

    /// Few rays in a leaf's box: each ray's triangles through its filter, as a single ray's
    /// leaf (traverse_wide.hpp).
    void by_ray(uint32_t index, uint32_t first, uint32_t count, int n) {
        for (int c = 0; c < n; ++c) {
            const int j = candidates_[c];
            if (!filter_[j]) filter_[j].emplace(scene_, ray_[j], kernel(j).shear());
            const double before = bound_[j], tmin = ray_[j].tmin;
            for (unsigned m = filter_[j]->candidates(scene_.leaf(index), count, bound_[j]); m; m &= m - 1)
                test_triangle(*kernel_[j], scene_, first + __builtin_ctz(m), tmin, bound_[j], hit_[j]);
            if (bound_[j] != before) came_closer(j);
        }
    }

    /// Ray j's kernel, made when first needed: most rays of a sweep meet few leaves, many none.
    const Kernel& kernel(int j) {
        if (!kernel_[j]) kernel_[j].emplace(ray_[j], context_);
        return *kernel_[j];
    }

    const Scene& scene_;
    const SweepRays& rays_;
    const CastContext& context_;
    double origin_[3];  ///< the rays' origin relative to the scene's anchor
    double reach_ = 0;  ///< a bound on |coordinates| relative to the anchor of boxes and origin
    int rows_ = 0, cols_ = 0, n_ = 0;
    double c_[3], p_[3], q_[3];
    LaneAxis axes_[3];  ///< c, p, q
    double far_ = HUGE_VAL;  ///< the greatest of the blocks' far bounds
    float far_limit_ = HUGE_VALF;  ///< boxes whose least c.x (float) lies beyond this are beyond far_
    Rect all_, blocks_[kMaxRays];
    int n_blocks_ = 0, block_first_[kMaxRays + 1], block_of_[kMaxRays];  ///< block b: rays block_first_[b] .. [b + 1] - 1
    // (the blocks' rectangles side by side, read four at a time: three more)
    double block_far_[kMaxRays + 3], block_a0_[kMaxRays + 3], block_a1_[kMaxRays + 3], block_b0_[kMaxRays + 3],
        block_b1_[kMaxRays + 3];
    std::size_t index_[kMaxRays];
    Ray ray_[kMaxRays];
    std::optional<Kernel> kernel_[kMaxRays];
    std::optional<TriangleFilter> filter_[kMaxRays];
    bool block_changed_[kMaxRays] = {};  ///< the blocks of rays that came closer in a leaf (came_closer)
    int changed_blocks_[kMaxRays], n_changed_ = 0;
    int candidates_[kMaxRays];  ///< the rays a leaf is tested on, and their projections
    double candidate_a_[kMaxRays + 3], candidate_b_[kMaxRays + 3];
    Hit<Real> hit_[kMaxRays];
    // (kBlock more: a block's rays are read kBlock at a time)
    double bound_[kMaxRays + kBlock], w_[kMaxRays + kBlock], a_[kMaxRays + kBlock], b_[kMaxRays + kBlock];
    std::vector<RowHistory> history_;  ///< by row of tiles
    std::vector<std::size_t> which_;   ///< a tile's rays, for trace_rays_interleaved
    InFlightChooser in_flight_;        ///< and how many of them in flight
    uint32_t hit_prims_[kMaxRays];     ///< the triangles a tile's rays hit
};

}  // namespace vrc
