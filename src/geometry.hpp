// Small value types shared by the builder, the traversal and the kernels.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <utility>
#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace vrc {

/// Four doubles (GCC/Clang vector extension: AVX where the CPU has it, SSE2 otherwise):
/// lanes of plane or edge tests evaluated at once.
using Double4 = double __attribute__((vector_size(32)));
using Mask4 = int64_t __attribute__((vector_size(32)));

/// Four rays in the lanes of Double4s (Ray's fields, the direction normalised as
/// Ray::normalize_direction does).
struct Rays4 {
    Double4 org[3], dir[3], tmin, tmax;
};

/// Whether any lane of a comparison holds.
inline bool any(Mask4 m) {
#if defined(__AVX__)
    return _mm256_movemask_pd(_mm256_castsi256_pd(__m256i(m))) != 0;
#else
    return (m[0] | m[1] | m[2] | m[3]) != 0;
#endif
}
/// The lanes of m that are set, as bits 0 to 3.
inline unsigned lane_bits(Mask4 m) {
#if defined(__AVX__)
    return unsigned(_mm256_movemask_pd(_mm256_castsi256_pd(__m256i(m))));
#else
    return unsigned(m[0] & 1) | unsigned(m[1] & 2) | unsigned(m[2] & 4) | unsigned(m[3] & 8);
#endif
}

/// Axis-aligned box in single precision. Stored boxes are rounded outward, so a box
/// always contains the double-precision triangles it bounds.
struct Box {
    float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                   std::numeric_limits<float>::infinity()};
    float hi[3] = {-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                   -std::numeric_limits<float>::infinity()};

    void grow(const Box& b) {
        for (int k = 0; k < 3; ++k) {
            lo[k] = b.lo[k] < lo[k] ? b.lo[k] : lo[k];  // not std::fmin: that is a libm call
            hi[k] = b.hi[k] > hi[k] ? b.hi[k] : hi[k];
        }
    }
    void grow(const float p[3]) {
        for (int k = 0; k < 3; ++k) {
            lo[k] = p[k] < lo[k] ? p[k] : lo[k];
            hi[k] = p[k] > hi[k] ? p[k] : hi[k];
        }
    }
    /// Half the surface area (the constant factor does not matter to the SAH); 0 when empty.
    [[nodiscard]] float half_area() const {
        const float dx = hi[0] - lo[0], dy = hi[1] - lo[1], dz = hi[2] - lo[2];
        if (!(dx >= 0.0f && dy >= 0.0f && dz >= 0.0f)) return 0.0f;
        return dx * dy + dy * dz + dz * dx;
    }
};

/// The float next to f above (below): std::nextafter without the libm call, which showed
/// in profiles of single rays.
inline float next_float(float f, bool up) {
    if (f != f) return f;
    if (f == 0) return up ? std::numeric_limits<float>::denorm_min() : -std::numeric_limits<float>::denorm_min();
    if (std::isinf(f)) return (f > 0) == up ? f : std::copysign(std::numeric_limits<float>::max(), f);
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    bits = (f > 0) == up ? bits + 1 : bits - 1;
    std::memcpy(&f, &bits, sizeof f);
    return f;
}

/// Largest float <= x and smallest float >= x: outward rounding of box corners.
inline float round_down(double x) {
    const float f = static_cast<float>(x);
    return static_cast<double>(f) > x ? next_float(f, false) : f;
}
inline float round_up(double x) {
    const float f = static_cast<float>(x);
    return static_cast<double>(f) < x ? next_float(f, true) : f;
}

/// Float bounds of x - a, rounded outward: below and above the exact difference, which the
/// double subtraction alone could miss by its own rounding (`err`, from a two-difference).
inline float relative_down(double x, double a) {
    const double d = x - a, bv = x - d, err = (x - (d + bv)) + (bv - a);  // d + err == x - a exactly
    float f = round_down(d);
    if (static_cast<double>(f) - d > err) f = next_float(f, false);
    return f;
}
inline float relative_up(double x, double a) {
    const double d = x - a, bv = x - d, err = (x - (d + bv)) + (bv - a);
    float f = round_up(d);
    if (static_cast<double>(f) - d < err) f = next_float(f, true);
    return f;
}

/// A ray in world space. The origin stays in double precision whatever the kernel's
/// precision, so kernels can subtract it from the vertices before rounding (work relative
/// to the ray origin, not to the world origin). `t` is in units of `dir`'s length;
/// `output(t)` converts it to what the caller asked for (its own t, or a camera depth).
struct Ray {
    double org[3];
    double dir[3];
    double tmin;
    double tmax;
    double t_unit = 1.0;  ///< output = t * t_unit * 2**t_exponent
    int t_exponent = 0;

    [[nodiscard]] double output(double t) const {
        const double scaled = t * t_unit;
        return (t_exponent > -500 && t_exponent < 500 && std::fabs(scaled) < 0x1p500 && std::fabs(scaled) > 0x1p-500)
                   ? scaled * power_of_two(t_exponent)
                   : std::ldexp(scaled, t_exponent);
    }

    /// Scales `dir` by a power of two (exactly) so that its largest component lies in
    /// [1, 2), with tmin, tmax and the output scale to match: directions of any magnitude,
    /// from subnormal to huge, then meet the kernels with no overflow in 1/d or the shear.
    void normalize_direction() {
        const double x = std::fabs(dir[0]), y = std::fabs(dir[1]), z = std::fabs(dir[2]);
        const double m = x > y ? (x > z ? x : z) : (y > z ? y : z);  // not std::fmax: a libm call, and no NaN comes here
        if (!(m > 0) || !std::isfinite(m)) return;
        if (m >= 0x1p-500 && m < 0x1p500) {
            // The common case without libm calls (they showed in profiles): the exponent from
            // the bits, and multiplications by exact powers of two that cannot under- or
            // overflow the direction here.
            uint64_t bits;
            std::memcpy(&bits, &m, sizeof bits);
            const int e = int((bits >> 52) & 0x7ff) - 1023;
            const double down = power_of_two(-e), up = power_of_two(e);
            for (double& c : dir) c *= down;
            tmin *= up;
            tmax *= up;
            t_exponent = -e;
            return;
        }
        const int e = std::ilogb(m);
        for (double& c : dir) c = std::ldexp(c, -e);
        tmin = std::ldexp(tmin, e);
        tmax = std::ldexp(tmax, e);
        t_exponent = -e;
    }

    /// 2**e for |e| <= 1022, built from its bits.
    static double power_of_two(int e) {
        const uint64_t bits = uint64_t(e + 1023) << 52;
        double x;
        std::memcpy(&x, &bits, sizeof x);
        return x;
    }
};

/// The watertight test's change of axes for a ray (Woop, Benthin and Wald, JCGT 2013): z
/// along the direction's largest component, x and y the next two in the order that keeps
/// triangles' winding, and the shear that takes the direction to (0, 0, 1/sz).
struct Shear {
    explicit Shear(const Ray& ray) {
        kz = 0;
        for (int k = 1; k < 3; ++k)
            if (std::fabs(ray.dir[k]) > std::fabs(ray.dir[kz])) kz = k;
        kx = (kz + 1) % 3;
        ky = (kx + 1) % 3;
        if (ray.dir[kz] < 0) std::swap(kx, ky);
        sx = ray.dir[kx] / ray.dir[kz];
        sy = ray.dir[ky] / ray.dir[kz];
        sz = 1.0 / ray.dir[kz];
    }
    int kx, ky, kz;
    double sx, sy, sz;
};

/// The closest hit found so far. `prim` indexes the scene's (BVH-ordered) triangles;
/// `b` holds the weights of the triangle's three points, in its own point order.
template <class Real>
struct Hit {
    double t = std::numeric_limits<double>::infinity();
    Real b[3] = {0, 0, 0};
    uint32_t prim = UINT32_MAX;
    [[nodiscard]] bool found() const { return prim != UINT32_MAX; }
};

}  // namespace vrc
