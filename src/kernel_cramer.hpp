// The seed lecture's Strategy II: barycentric coordinates and t from a 3x3 linear system
// solved with an explicit inverse (Cramer's rule).
#pragma once

#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// With the ray origin at 0, t d = l1 P1 + l2 P2 + (1 - l1 - l2) P3 rearranges to
/// [P3 - P1 | P3 - P2 | d] (l1, l2, t) = P3. The matrix is inverted explicitly (cofactors
/// over the determinant, the lecture's snippet) and the solution is its product with P3.
/// Inside when 0 <= l1, l2, l3 <= 1. A singular matrix (ray parallel to the plane) misses.
/// det = d . n with n = (P2 - P1) x (P3 - P1), so front faces have det < 0.
template <class Real>
class SeedCramer : public PointKernel<SeedCramer<Real>> {
   public:
    SeedCramer(const Ray& ray, const CastContext& context) : ray_(ray, context) {}

    bool operator()(const double* pa, const double* pb, const double* pc, double tmin, double tmax, double& t,
                    Real b[3]) const {
        Real p1[3], p2[3], p3[3];
        relative(pa, ray_.org, p1);
        relative(pb, ray_.org, p2);
        relative(pc, ray_.org, p3);
        // m(r, c): column 0 = P3 - P1, column 1 = P3 - P2, column 2 = d.
        Real m[3][3];
        for (int r = 0; r < 3; ++r) {
            m[r][0] = p3[r] - p1[r];
            m[r][1] = p3[r] - p2[r];
            m[r][2] = ray_.dir[r];
        }
        const Real det = m[0][0] * (m[1][1] * m[2][2] - m[2][1] * m[1][2]) -
                         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
                         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        if (det == 0 || (ray_.cull && det > 0)) return false;
        const Real inv = Real(1) / det;
        Real minv[3][3];
        minv[0][0] = (m[1][1] * m[2][2] - m[2][1] * m[1][2]) * inv;
        minv[0][1] = (m[0][2] * m[2][1] - m[0][1] * m[2][2]) * inv;
        minv[0][2] = (m[0][1] * m[1][2] - m[0][2] * m[1][1]) * inv;
        minv[1][0] = (m[1][2] * m[2][0] - m[1][0] * m[2][2]) * inv;
        minv[1][1] = (m[0][0] * m[2][2] - m[0][2] * m[2][0]) * inv;
        minv[1][2] = (m[1][0] * m[0][2] - m[0][0] * m[1][2]) * inv;
        minv[2][0] = (m[1][0] * m[2][1] - m[2][0] * m[1][1]) * inv;
        minv[2][1] = (m[2][0] * m[0][1] - m[0][0] * m[2][1]) * inv;
        minv[2][2] = (m[0][0] * m[1][1] - m[1][0] * m[0][1]) * inv;
        const Real l1 = minv[0][0] * p3[0] + minv[0][1] * p3[1] + minv[0][2] * p3[2];
        const Real l2 = minv[1][0] * p3[0] + minv[1][1] * p3[1] + minv[1][2] * p3[2];
        const Real ti = minv[2][0] * p3[0] + minv[2][1] * p3[1] + minv[2][2] * p3[2];
        const Real l3 = Real(1) - l1 - l2;
        if (!(l1 >= 0 && l1 <= 1 && l2 >= 0 && l2 <= 1 && l3 >= 0 && l3 <= 1)) return false;
        if (!(ti >= tmin && ti <= tmax)) return false;
        t = ti;
        b[0] = l1;
        b[1] = l2;
        b[2] = l3;
        return true;
    }

   private:
    RayFrame<Real> ray_;
};

}  // namespace vrc
