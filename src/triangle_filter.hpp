// Four triangles against one ray in the lanes of AVX registers: which certainly miss it.
// A leaf's triangles go through this first; only the rest meet the exact kernel.
#pragma once

#include <immintrin.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "bvh.hpp"
#include "geometry.hpp"

namespace vrc {

/// The watertight test's edge functions (Woop, Benthin and Wald, JCGT 2013) in double for
/// four triangles at once. A lane is rejected only when the answer is certain: two edge
/// functions of opposite signs, each larger than its rounding-error bound (then their
/// signs are the exact ones, which every kernel here also finds, kernel_watertight.hpp),
/// or all three vertices' depths along the ray beyond [tmin, bound] by far more than any
/// kernel's rounding of t (relative 2^-9). Everything else, hits and
/// near-misses alike, goes on to the kernel, so results are the kernel's, bit for bit.
/// In double, not in eight float lanes: the bound grows with a triangle's distance from the
/// ray's origin (the sheared coordinates' magnitudes), and in single precision it lets
/// through most of a large mesh's small, distant triangles.
#if defined(__AVX__)
class TriangleFilter {
   public:
    TriangleFilter(const Ray& ray, const Shear& shear) {
        axis_[0] = shear.kx;
        axis_[1] = shear.ky;
        axis_[2] = shear.kz;
        for (int k = 0; k < 3; ++k) org_[k] = _mm256_set1_pd(ray.org[k]);
        sx_ = _mm256_set1_pd(shear.sx);
        sy_ = _mm256_set1_pd(shear.sy);
        sz_ = _mm256_set1_pd(shear.sz);
    }

    /// Bits of the lanes among triangles first .. first + n - 1 (n <= 4, leaf order) that
    /// may meet the ray with tmin <= t <= bound.
    [[nodiscard, gnu::always_inline]] unsigned candidates(const Scene& scene, uint32_t first, uint32_t n, double tmin, double bound) const {
        __m256d p[3][3];  // [vertex][axis: the ray's kx, ky, kz], relative to the origin
        const uint32_t* tri = scene.triangles.data() + 3 * std::size_t(first);
        for (int v = 0; v < 3; ++v) {
            __m256d rows[4];
            for (uint32_t lane = 0; lane < 4; ++lane)  // (missing lanes repeat the first triangle)
                rows[lane] = _mm256_maskload_pd(scene.point(tri[3 * (lane < n ? lane : 0) + v]), kXyz);
            const __m256d t0 = _mm256_unpacklo_pd(rows[0], rows[1]), t1 = _mm256_unpackhi_pd(rows[0], rows[1]);
            const __m256d t2 = _mm256_unpacklo_pd(rows[2], rows[3]), t3 = _mm256_unpackhi_pd(rows[2], rows[3]);
            const __m256d xyz[3] = {_mm256_permute2f128_pd(t0, t2, 0x20), _mm256_permute2f128_pd(t1, t3, 0x20),
                                    _mm256_permute2f128_pd(t0, t2, 0x31)};
            for (int k = 0; k < 3; ++k) p[v][k] = _mm256_sub_pd(xyz[axis_[k]], org_[axis_[k]]);
        }
        __m256d sxv[3], syv[3], mx[3], my[3];  // sheared coordinates and their magnitudes
        for (int v = 0; v < 3; ++v) {
            const __m256d zx = _mm256_mul_pd(sx_, p[v][2]), zy = _mm256_mul_pd(sy_, p[v][2]);
            sxv[v] = _mm256_sub_pd(p[v][0], zx);
            syv[v] = _mm256_sub_pd(p[v][1], zy);
            mx[v] = _mm256_add_pd(abs(p[v][0]), abs(zx));
            my[v] = _mm256_add_pd(abs(p[v][1]), abs(zy));
        }
        // u: edge (c, b), v: (a, c), w: (b, a), as the kernel pairs them
        const int pairs[3][2] = {{2, 1}, {0, 2}, {1, 0}};
        __m256d edge[3], negative = _mm256_setzero_pd(), positive = _mm256_setzero_pd();
        const __m256d bound_factor = _mm256_set1_pd(kEdgeBound);
        for (int e = 0; e < 3; ++e) {
            const int i = pairs[e][0], j = pairs[e][1];
            edge[e] = _mm256_sub_pd(_mm256_mul_pd(sxv[i], syv[j]), _mm256_mul_pd(syv[i], sxv[j]));
            const __m256d scale = _mm256_add_pd(_mm256_mul_pd(mx[i], my[j]), _mm256_mul_pd(my[i], mx[j]));
            const __m256d margin = _mm256_mul_pd(bound_factor, scale);
            negative = _mm256_or_pd(negative, _mm256_cmp_pd(edge[e], _mm256_sub_pd(_mm256_setzero_pd(), margin), _CMP_LT_OQ));
            positive = _mm256_or_pd(positive, _mm256_cmp_pd(edge[e], margin, _CMP_GT_OQ));
        }
        const __m256d crossing = _mm256_and_pd(negative, positive);
        // A hit's t is the average of the vertices' depths (sz times their kz offsets)
        // weighted by its barycentric coordinates: it lies between the least and the greatest.
        __m256d near = _mm256_mul_pd(sz_, p[0][2]), far = near;
        for (int v = 1; v < 3; ++v) {
            const __m256d z = _mm256_mul_pd(sz_, p[v][2]);
            near = _mm256_min_pd(near, z);
            far = _mm256_max_pd(far, z);
        }
        const __m256d relative = _mm256_set1_pd(kDepthBound);
        const __m256d before = _mm256_cmp_pd(_mm256_add_pd(far, _mm256_mul_pd(relative, abs(far))), _mm256_set1_pd(tmin), _CMP_LT_OQ);
        const __m256d after = _mm256_cmp_pd(_mm256_sub_pd(near, _mm256_mul_pd(relative, abs(near))), _mm256_set1_pd(bound), _CMP_GT_OQ);
        const __m256d rejected = _mm256_or_pd(crossing, _mm256_or_pd(before, after));
        return ~unsigned(_mm256_movemask_pd(rejected)) & ((1u << n) - 1);
    }

   private:
    /// Each sheared coordinate carries at most about 4 ulps of its magnitude (the
    /// difference to the origin, the shear's product and difference), an edge function about
    /// 10 of its scale: 16 eps bounds it with a wide margin, as in the kernel.
    static constexpr double kEdgeBound = 16 * std::numeric_limits<double>::epsilon();
    /// The depths carry three roundings; a kernel's t (float or double) at most about 10^3
    /// float ulps of itself before it is refined in double (kernel_watertight.hpp).
    static constexpr double kDepthBound = 0x1p-9;
    static inline const __m256i kXyz = _mm256_setr_epi64x(-1, -1, -1, 0);
    static __m256d abs(__m256d x) { return _mm256_andnot_pd(_mm256_set1_pd(-0.0), x); }
    int axis_[3];
    __m256d org_[3], sx_, sy_, sz_;
};
#else
/// Without AVX every triangle of a leaf meets the kernel (the same answers, more tests).
class TriangleFilter {
   public:
    TriangleFilter(const Ray&, const Shear&) {}
    [[nodiscard]] unsigned candidates(const Scene&, uint32_t, uint32_t n, double, double) const {
        return (1u << n) - 1;
    }
};
#endif

}  // namespace vrc
