// A leaf's eight triangles against one ray in eight float lanes: which certainly miss it.
// A leaf's triangles go through this first; only the rest meet the exact kernel.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "bvh.hpp"
#include "geometry.hpp"
#include "lanes.hpp"

namespace vrc {

/// The watertight test's edge functions (Woop, Benthin and Wald, JCGT 2013) in single
/// precision for a leaf's triangles (LeafBlock: coordinates relative to the scene's anchor,
/// scaled into [-1, 1], quantized within the leaf's box). A lane is rejected only when the
/// answer is certain: two edge functions of opposite signs, each larger than its error
/// bound (then the exact edge functions, of the double points and the kernel's own shear,
/// have those signs, which every kernel here also finds, kernel_watertight.hpp), or all
/// three corners' depths along the ray beyond [tmin, bound] by more than any kernel's
/// rounding of t (relative 2^-9) and their own errors. Everything else goes on to the
/// kernel, so results are the kernel's, bit for bit.
///
/// The bounds. With u = 2^-24, e the leaf's quantization error and P a bound on every
/// coordinate relative to the ray's origin (1, the scene's scaled reach, plus the scaled
/// origin's distance from the anchor), a corner's coordinate relative to the origin
/// carries at most 5u P + e (the origin's rounding to float, the leaf corner's difference
/// to it, the product and sum of the dequantization), and a sheared coordinate
/// x = p_x - s_x p_z (|s_x| <= 1, rounded to float) at most 14u P + 2e: d = 16u P + 4e
/// bounds it. An edge function x_i y_j - y_i x_j then differs from the exact one by at most
/// d (S_i + S_j) + 2 d^2 + 2.01u S_i S_j, with S = |x| + |y| of the computed coordinates;
/// the filter takes 4 d^2 and 4u for the last two (the bound's own roundings are covered by
/// the margins of the factors). A depth s_z p_z (|s_z| <= 1) carries at most 7u P + e; the
/// filter takes 16u P + 2e and a relative 2^-8. The error grows with the distance from the
/// ray's origin only through P, an absolute bound: a small triangle far from the origin is
/// decided as surely as a near one (bounds from the edge functions' magnitudes, as in the
/// kernel, would not allow it).
class TriangleFilter {
   public:
    TriangleFilter(const Scene& scene, const Ray& ray, const Shear& shear)
        : axis_{shear.kx, shear.ky, shear.kz},
          sx_(static_cast<float>(shear.sx)),
          sy_(static_cast<float>(shear.sy)),
          sz_(static_cast<float>(shear.sz)),
          scale_(scene.leaf_scale),
          tmin_(static_cast<float>(ray.tmin * scale_)) {
        float reach = 0;
        for (int k = 0; k < 3; ++k) {
            org_[k] = static_cast<float>((ray.org[axis_[k]] - scene.anchor[axis_[k]]) * scale_);
            reach = std::max(reach, std::fabs(org_[k]));
        }
        // Beyond these the bounds could overflow (or the scale is off): every lane goes on
        // to the kernel. (|sx|, |sy| <= 1 by the choice of kz.)
        usable_ = scale_ > 0 && reach < 0x1p40f && std::fabs(shear.sz) <= 1;
        delta_ = 0x1p-20f * (1 + reach) * (1 + 0x1p-20f);
    }

    /// Bits of the lanes among the first `n` of `block` that may meet the ray with
    /// tmin <= t <= bound. With `certain` (kCertain), also the bits of those that surely
    /// meet it there, facing the ray where `culling` asks: all three edge functions of one
    /// sign, each beyond its error bound, and all three corners' depths within
    /// [tmin, bound] by the margins that reject the others. The kernel would only confirm
    /// such a hit (its edge signs are the exact ones, its t within 2^-9 of the exact one),
    /// which is all an any-hit query asks.
    template <bool kCertain = false>
    [[nodiscard, gnu::always_inline]] unsigned candidates(const LeafBlock& block, uint32_t n, double bound,
                                                          bool culling = false, unsigned* certain = nullptr) const {
        const unsigned all = (1u << n) - 1;
        if constexpr (kCertain) *certain = 0;
        if (!usable_) return all;
        Lane8 x[3], y[3], s[3], z[3];
        const Lane8 step[3] = {lanes_set(block.step[axis_[0]]), lanes_set(block.step[axis_[1]]), lanes_set(block.step[axis_[2]])};
        const Lane8 corner[3] = {lanes_set(block.lo[axis_[0]] - org_[0]), lanes_set(block.lo[axis_[1]] - org_[1]),
                                 lanes_set(block.lo[axis_[2]] - org_[2])};
        for (int v = 0; v < 3; ++v) {
            const Lane8 px = lanes_fmadd(lanes_load_u8(block.row(3 * v + axis_[0], n)), step[0], corner[0]);
            const Lane8 py = lanes_fmadd(lanes_load_u8(block.row(3 * v + axis_[1], n)), step[1], corner[1]);
            const Lane8 pz = lanes_fmadd(lanes_load_u8(block.row(3 * v + axis_[2], n)), step[2], corner[2]);
            x[v] = lanes_fmadd(lanes_set(-sx_), pz, px);
            y[v] = lanes_fmadd(lanes_set(-sy_), pz, py);
            s[v] = lanes_add(lanes_abs(x[v]), lanes_abs(y[v]));
            z[v] = lanes_mul(lanes_set(sz_), pz);
        }
        const float d = delta_ + 4 * block.error;
        const Lane8 delta = lanes_set(d), delta2 = lanes_set(4 * d * d), rounding = lanes_set(0x1p-22f);
        // u: edge (c, b), v: (a, c), w: (b, a), as the kernel pairs them
        const int pairs[3][2] = {{2, 1}, {0, 2}, {1, 0}};
        Lane8 negative = lanes_set(0.0f), positive = negative;
        unsigned all_negative = all, all_positive = all;  // (kCertain)
        for (const auto& pair : pairs) {
            const int i = pair[0], j = pair[1];
            const Lane8 edge = lanes_fmadd(x[i], y[j], lanes_neg(lanes_mul(y[i], x[j])));
            const Lane8 margin = lanes_fmadd(lanes_mul(rounding, s[i]), s[j], lanes_fmadd(delta, lanes_add(s[i], s[j]), delta2));
            const Lane8 below = lanes_lt(edge, lanes_neg(margin)), above = lanes_lt(margin, edge);
            negative = lanes_or(negative, below);
            positive = lanes_or(positive, above);
            if constexpr (kCertain) all_negative &= lanes_bits(below), all_positive &= lanes_bits(above);
        }
        // A hit's t is the average of the corners' depths weighted by its barycentric
        // coordinates: it lies between the least and the greatest.
        const Lane8 near = lanes_min(lanes_min(z[0], z[1]), z[2]), far = lanes_max(lanes_max(z[0], z[1]), z[2]);
        const Lane8 relative = lanes_set(0x1p-8f), slack = lanes_set(delta_ + 2 * block.error);
        // (tmin and the bound rounded to nearest: their relative error, 2^-24, vanishes in
        // the relative margin, which exceeds the kernel's 2^-9 by far more)
        const Lane8 far_most = lanes_add(far, lanes_fmadd(relative, lanes_abs(far), slack));
        const Lane8 near_least = lanes_sub(near, lanes_fmadd(relative, lanes_abs(near), slack));
        const Lane8 tmin = lanes_set(tmin_), last = lanes_set(static_cast<float>(bound * scale_));
        const Lane8 before = lanes_lt(far_most, tmin), after = lanes_lt(last, near_least);
        const Lane8 rejected = lanes_or(lanes_and(negative, positive), lanes_or(before, after));
        if constexpr (kCertain)
            *certain = (all_positive | (culling ? 0u : all_negative)) & lanes_le(tmin, near_least) & lanes_le(far_most, last);
        return ~lanes_bits(rejected) & all;
    }

   private:
    int axis_[3];   ///< the shear's kx, ky, kz
    float sx_, sy_, sz_;
    double scale_;
    float tmin_;    ///< scaled
    float org_[3];  ///< the ray's origin along kx, ky, kz, relative to the anchor, scaled
    float delta_;   ///< 16u P
    bool usable_;
};

}  // namespace vrc
