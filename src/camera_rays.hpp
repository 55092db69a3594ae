// Camera rays (the seed lecture's model) and rays given as arrays, behind one interface
// the tile renderer iterates over.
#pragma once

#include <cstddef>
#include <algorithm>
#include <cmath>
#include <cstdint>

#include "geometry.hpp"
#include "memory.hpp"

namespace vrc {

/// Camera in world space: eye, orthonormal right (u), up (v) and backward (w) axes, the
/// image window w x h at distance d, nx x ny pixels, and the depth range [near, far].
struct CameraSpec {
    double eye[3], u[3], v[3], w[3];
    double d, width, height, near, far;
    double shift_x, shift_y;  ///< the window's centre on the image plane (right, up of the view axis)
    int64_t nx, ny;
    bool parallel;
};

/// One ray per pixel. Pixel (i, r) is output element i + r nx, row r = 0 at the bottom
/// (VTK image order); its centre is the seed's formula with j = ny - 1 - r counted from
/// the top: x = sx - w/2 + w/nx (i + 1/2), y = sy + h/2 - h/ny (j + 1/2), z = -d, with
/// (sx, sy) the window's shift (an off-centre principal point; 0 for the seed's camera).
/// Perspective rays start at the eye with direction P_ij, so t = 1 is the image plane and
/// depth = t d. Parallel rays start at (x, y, 0) with direction (0, 0, -1): depth = t.
class CameraRays {
   public:
    explicit CameraRays(const CameraSpec& c)
        : c_(c), pitch_x_(c.width / double(c.nx)), pitch_y_(c.height / double(c.ny)),
          tmin_(c.parallel ? c.near : c.near / c.d), tmax_(c.parallel ? c.far : c.far / c.d) {
        for (int k = 0; k < 3; ++k) dw_[k] = c.d * c.w[k];
    }
    [[nodiscard]] std::size_t size() const { return std::size_t(c_.nx) * std::size_t(c_.ny); }

    [[nodiscard]] Ray ray(std::size_t pixel) const {
        return ray(int64_t(pixel % std::size_t(c_.nx)), int64_t(pixel / std::size_t(c_.nx)));
    }
    /// The ray of pixel column i, row r.
    [[nodiscard]] Ray ray(int64_t i, int64_t r) const {
        Ray ray;
        set_ray(ray, i, r);
        return ray;
    }
    /// Sets `ray` to the ray of pixel column i, row r, in place (the tiles keep a ray per
    /// pixel: no copy of one).
    void set_ray(Ray& ray, int64_t i, int64_t r) const {
        const int64_t j = c_.ny - 1 - r;
        // (divisions done once, in the constructor: the same values)
        const double x = (c_.shift_x - c_.width * 0.5) + pitch_x_ * (double(i) + 0.5);
        const double y = (c_.shift_y + c_.height * 0.5) - pitch_y_ * (double(j) + 0.5);
        ray.tmin = tmin_;
        ray.tmax = tmax_;
        if (c_.parallel) {
            for (int k = 0; k < 3; ++k) {
                ray.org[k] = c_.eye[k] + x * c_.u[k] + y * c_.v[k];
                ray.dir[k] = -c_.w[k];
            }
        } else {
            for (int k = 0; k < 3; ++k) {
                ray.org[k] = c_.eye[k];
                ray.dir[k] = x * c_.u[k] + y * c_.v[k] - dw_[k];
            }
        }
        ray.t_unit = t_unit();
        ray.t_exponent = 0;
        ray.normalize_direction();
    }

    /// Depth per unit of t (before a ray's normalisation): d, or 1 for parallel rays.
    [[nodiscard]] double t_unit() const { return c_.parallel ? 1.0 : c_.d; }

    /// The rays of four pixels (columns i, rows r) in lanes, each bit for bit as set_ray
    /// makes it, and in `exponent` each one's Ray::t_exponent. Returns the lanes made so:
    /// the others' directions lie beyond normalize_direction's common case (set_ray's).
    unsigned rays4(const int64_t i[4], const int64_t r[4], Rays4& out, int exponent[4]) const {
        using D = Double4;
        using M = Mask4;
        const D col = D{double(i[0]), double(i[1]), double(i[2]), double(i[3])};
        const D row = D{double(c_.ny - 1 - r[0]), double(c_.ny - 1 - r[1]), double(c_.ny - 1 - r[2]), double(c_.ny - 1 - r[3])};
        const D x = (c_.shift_x - c_.width * 0.5) + pitch_x_ * (col + 0.5);
        const D y = (c_.shift_y + c_.height * 0.5) - pitch_y_ * (row + 0.5);
        const auto splat = [](double v) { return D{v, v, v, v}; };  // (0 + v would turn -0 into +0)
        for (int k = 0; k < 3; ++k) {
            if (c_.parallel) {
                out.org[k] = c_.eye[k] + x * c_.u[k] + y * c_.v[k];
                out.dir[k] = splat(-c_.w[k]);
            } else {
                out.org[k] = splat(c_.eye[k]);
                out.dir[k] = x * c_.u[k] + y * c_.v[k] - dw_[k];
            }
        }
        const auto abs = [](D v) { return D(M(v) & INT64_MAX); };
        const D ax = abs(out.dir[0]), ay = abs(out.dir[1]), az = abs(out.dir[2]);
        const D m = ax > ay ? (ax > az ? ax : az) : (ay > az ? ay : az);
        const M e = ((M(m) >> 52) & 0x7ff) - 1023;
        const D down = D((1023 - e) << 52), up = D((1023 + e) << 52);
        for (D& d : out.dir) d *= down;
        out.tmin = tmin_ * up;
        out.tmax = tmax_ * up;
        for (int l = 0; l < 4; ++l) exponent[l] = -int(e[l]);
        const M common = (m >= 0x1p-500) & (m < 0x1p500);
        return lane_bits(common);
    }

    /// Square tiles of kTile x kTile pixels: neighbouring rays traverse the same nodes.
    /// Through a BVH a tile's rays go as one packet (traverse_tile.hpp). Large enough to
    /// share node tests among many rays, small enough that a node behind the hits already
    /// found is culled (at 2x2-pixel quads) and that two workers stay balanced: 64 was the
    /// fastest of 16, 32 and 64 on 1024x1024 views of the benchmarks' scenes, and no slower
    /// at 256x256 (benchmarks/compare_builds.py). (64 is also the most a row's bits hold:
    /// TileTracer.)
    static constexpr int64_t kTile = 64;
    [[nodiscard]] std::size_t n_tiles() const { return std::size_t(tiles_x() * ((c_.ny + kTile - 1) / kTile)); }
    template <class F>
    void for_each_in_tile(std::size_t tile, F&& f) const {
        const TilePixels p = tile_pixels(tile);
        for (int64_t r = p.r0; r <= p.r1; ++r)
            for (int64_t i = p.i0; i <= p.i1; ++i) f(std::size_t(i + r * c_.nx));
    }

    /// A tile's columns i0..i1 and rows r0..r1 (inclusive).
    struct TilePixels {
        int64_t i0, i1, r0, r1;
    };
    [[nodiscard]] TilePixels tile_pixels(std::size_t tile) const {
        const int64_t i0 = int64_t(tile) % tiles_x() * kTile, r0 = int64_t(tile) / tiles_x() * kTile;
        return {i0, std::min(i0 + kTile, c_.nx) - 1, r0, std::min(r0 + kTile, c_.ny) - 1};
    }

    /// Pixel coordinates of a point as ratios of linear forms of q = P - eye: column
    /// (col.q + col0) / (den.q + den0), row likewise; pixel (i, r)'s ray passes through
    /// column i, row r. The denominator is the depth for a pinhole, 1 for a parallel camera.
    /// `margin` (pixels) bounds how far a ray strays from its pixel centre by rounding (of
    /// its direction, or of its origin for a parallel camera) plus the rounding of the
    /// projection itself for points with den > kMinDen |q|_1: 64 roundings of the ray's
    /// terms, and 10^4 of the projection's (its terms reach (nx + ny)(1 + d per) |q|_1 / den,
    /// at most 10^3 of that), plus 10^-5 pixels, well above both at common sizes (about
    /// 10^-11 and 10^-5 at 1024 pixels), against an error in this count.
    struct PixelMap {
        double col[3], row[3], den[3], depth[3];
        double col0, row0, den0, margin;
        static constexpr double kMinDen = 1e-3;
    };
    [[nodiscard]] PixelMap pixel_map() const {
        PixelMap m{};
        const double nx = double(c_.nx), ny = double(c_.ny), eps = std::numeric_limits<double>::epsilon();
        const double per_x = nx / c_.width, per_y = ny / c_.height;  // pixels per unit of the image plane
        // pixel coordinates of the view axis: the window's centre, shifted
        const double axis_col = nx * 0.5 - 0.5 - per_x * c_.shift_x, axis_row = ny * 0.5 - 0.5 - per_y * c_.shift_y;
        for (int k = 0; k < 3; ++k) {
            m.depth[k] = -c_.w[k];
            if (c_.parallel) {
                m.col[k] = per_x * c_.u[k];
                m.row[k] = per_y * c_.v[k];
                m.den[k] = 0;
            } else {
                m.col[k] = c_.d * per_x * c_.u[k] - axis_col * c_.w[k];
                m.row[k] = c_.d * per_y * c_.v[k] - axis_row * c_.w[k];
                m.den[k] = -c_.w[k];
            }
        }
        const double per = std::max(per_x, per_y);
        const double eye = std::max(std::fabs(c_.eye[0]), std::max(std::fabs(c_.eye[1]), std::fabs(c_.eye[2])));
        const double window = c_.width + c_.height + std::fabs(c_.shift_x) + std::fabs(c_.shift_y);
        if (c_.parallel) {
            m.col0 = axis_col;
            m.row0 = axis_row;
            m.den0 = 1;
            m.margin = 1e-5 + 64 * eps * (eye + window) * per;
        } else {
            m.col0 = m.row0 = m.den0 = 0;
            const double scale = window + c_.d;
            m.margin = 1e-5 + 64 * eps * scale * per + 1e4 * eps * (nx + ny) * (1 + c_.d * per);
        }
        return m;
    }
    [[nodiscard]] const CameraSpec& spec() const { return c_; }

    /// The seed's bounding-volume test, per tile: project the scene's box (given relative to
    /// `anchor`) into the image and keep the pixel rectangle that can see it (span). Tiles
    /// outside it are misses without traversal.
    void restrict_to(const Box& box, const double anchor[3]) { span_ = span(box, anchor); }

    /// Whether any pixel may see into a box (relative to `anchor`; see span).
    [[nodiscard]] bool sees(const Box& box, const double anchor[3]) const {
        return pixels(span(box, anchor)) != 0;
    }

    /// Whether any pixel of the image may see the scene (see restrict_to).
    [[nodiscard]] bool may_hit() const { return pixels_may_hit() != 0; }
    /// How many pixels may see the scene (see restrict_to).
    [[nodiscard]] std::size_t pixels_may_hit() const { return pixels(span_); }
    /// Whether any pixel of the tile may see the scene (see restrict_to).
    [[nodiscard]] bool tile_may_hit(std::size_t tile) const {
        const TilePixels p = tile_pixels(tile);
        return p.i0 <= span_.i_hi && p.i1 >= span_.i_lo && p.r0 <= span_.r_hi && p.r1 >= span_.r_lo;
    }

   private:
    /// Columns [i_lo, i_hi] and rows [r_lo, r_hi] (clamped to [-1, n]) of the pixels that
    /// may see into a box: its corners projected, a pixel of margin for the roundings. None
    /// (i_lo > i_hi) for a box wholly outside the depth range (behind the eye, say); every
    /// pixel for one reaching behind a pinhole eye's plane, which cannot be projected.
    struct Span {
        int64_t i_lo = INT64_MIN / 2, i_hi = INT64_MAX / 2, r_lo = INT64_MIN / 2, r_hi = INT64_MAX / 2;
    };
    [[nodiscard]] Span span(const Box& box, const double anchor[3]) const {
        constexpr Span kNone{INT64_MAX / 2, INT64_MIN / 2, INT64_MAX / 2, INT64_MIN / 2};  // meets no tile
        if (!(box.lo[0] <= box.hi[0])) return kNone;  // empty scene: nothing can be hit
        double rel[8][3], depth[8], near_depth = HUGE_VAL, far_depth = -HUGE_VAL, size = 0;
        for (int corner = 0; corner < 8; ++corner) {
            double* q = rel[corner];
            for (int k = 0; k < 3; ++k)
                q[k] = (anchor[k] - c_.eye[k]) + double((corner >> k & 1) ? box.hi[k] : box.lo[k]);
            depth[corner] = -(q[0] * c_.w[0] + q[1] * c_.w[1] + q[2] * c_.w[2]);
            near_depth = std::min(near_depth, depth[corner]), far_depth = std::max(far_depth, depth[corner]);
            size = std::max(size, std::fabs(q[0]) + std::fabs(q[1]) + std::fabs(q[2]));
        }
        const double slack = 1e-9 * size;  // far above the rounding of these depths
        if (far_depth + slack < c_.near || near_depth - slack > c_.far) return kNone;
        double lo_i = HUGE_VAL, hi_i = -HUGE_VAL, lo_r = HUGE_VAL, hi_r = -HUGE_VAL;
        for (int corner = 0; corner < 8; ++corner) {
            const double* q = rel[corner];
            double x = q[0] * c_.u[0] + q[1] * c_.u[1] + q[2] * c_.u[2];
            double y = q[0] * c_.v[0] + q[1] * c_.v[1] + q[2] * c_.v[2];
            if (!c_.parallel) {
                if (!(depth[corner] > 1e-9 * (std::fabs(x) + std::fabs(y)))) return Span{};  // reaches behind the eye
                x *= c_.d / depth[corner];
                y *= c_.d / depth[corner];
            }
            // pixel coordinates: column i, and row r counted from the bottom
            const double i = (x - c_.shift_x + c_.width * 0.5) / pitch_x_ - 0.5;
            const double r = (y - c_.shift_y + c_.height * 0.5) / pitch_y_ - 0.5;
            lo_i = std::min(lo_i, i), hi_i = std::max(hi_i, i);
            lo_r = std::min(lo_r, r), hi_r = std::max(hi_r, r);
        }
        const auto clamp = [](double v, int64_t n) { return int64_t(std::max(-1.0, std::min(double(n), v))); };
        return Span{clamp(std::floor(lo_i) - 1, c_.nx), clamp(std::ceil(hi_i) + 1, c_.nx), clamp(std::floor(lo_r) - 1, c_.ny),
                    clamp(std::ceil(hi_r) + 1, c_.ny)};
    }
    [[nodiscard]] std::size_t pixels(const Span& s) const {
        const int64_t i0 = std::max<int64_t>(s.i_lo, 0), i1 = std::min(s.i_hi, c_.nx - 1);
        const int64_t r0 = std::max<int64_t>(s.r_lo, 0), r1 = std::min(s.r_hi, c_.ny - 1);
        return i0 <= i1 && r0 <= r1 ? std::size_t(i1 - i0 + 1) * std::size_t(r1 - r0 + 1) : 0;
    }
    [[nodiscard]] int64_t tiles_x() const { return (c_.nx + kTile - 1) / kTile; }
    CameraSpec c_;
    double pitch_x_, pitch_y_, tmin_, tmax_, dw_[3];  // the image plane's pixel size, t's range, d w
    Span span_;  // the pixels that may see the scene (restrict_to): every one until restricted
};

/// Rays from (n, 3) origin and direction arrays (with `one_origin`, a single origin row
/// for all); the output is the ray parameter t.
class ArrayRays {
   public:
    ArrayRays(const double* origins, const double* directions, std::size_t n, double tmin, double tmax,
              bool one_origin = false)
        : o_(origins), d_(directions), n_(n), o_stride_(one_origin ? 0 : 3), tmin_(tmin), tmax_(tmax) {}
    [[nodiscard]] std::size_t size() const { return n_; }
    [[nodiscard]] Ray ray(std::size_t k) const {
        Ray ray;
        for (int a = 0; a < 3; ++a) {
            ray.org[a] = o_[o_stride_ * k + a];
            ray.dir[a] = d_[3 * k + a];
        }
        ray.tmin = tmin_;
        ray.tmax = tmax_;
        ray.normalize_direction();
        return ray;
    }

    /// Asks the cache for ray k's origin and direction (searches in flight take rays in
    /// order, but among their scattered reads the hardware's prefetcher did not keep up).
    void prefetch(std::size_t k) const {
        prefetch_line(o_ + o_stride_ * k);
        prefetch_line(d_ + 3 * k);
    }

    static constexpr std::size_t kChunk = 1024;
    [[nodiscard]] std::size_t n_tiles() const { return (n_ + kChunk - 1) / kChunk; }
    template <class F>
    void for_each_in_tile(std::size_t tile, F&& f) const {
        for (std::size_t k = tile * kChunk; k < std::min(n_, (tile + 1) * kChunk); ++k) f(k);
    }
    [[nodiscard]] bool tile_may_hit(std::size_t) const { return true; }

   private:
    const double *o_, *d_;
    std::size_t n_, o_stride_;
    double tmin_, tmax_;
};

}  // namespace vrc
