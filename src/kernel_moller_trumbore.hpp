// Moller and Trumbore, "Fast, Minimum Storage Ray-Triangle Intersection", Journal of
// Graphics Tools 2(1), 1997.
#pragma once

#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// Solves o + t d = (1 - u - v) P1 + u P2 + v P3 by Cramer's rule with scalar triple
/// products. No epsilon: only an exactly singular system (det == 0) is rejected, so the
/// comparison with the other kernels measures rounding alone. Each triangle evaluates its
/// edges from its own first vertex, so neighbours may disagree on a shared edge (leaks).
/// det = -d . n, so front faces have det > 0.
template <class Real>
class MollerTrumbore : public PointKernel<MollerTrumbore<Real>> {
   public:
    MollerTrumbore(const Ray& ray, const CastContext& context) : ray_(ray, context) {}

    bool operator()(const double* pa, const double* pb, const double* pc, double tmin, double tmax, double& t,
                    Real b[3]) const {
        Real p1[3], p2[3], p3[3], e1[3], e2[3], pvec[3], qvec[3];
        relative(pa, ray_.org, p1);
        relative(pb, ray_.org, p2);
        relative(pc, ray_.org, p3);
        sub(p2, p1, e1);
        sub(p3, p1, e2);
        cross(ray_.dir, e2, pvec);
        const Real det = dot(e1, pvec);
        if (det == 0 || (ray_.cull && det < 0)) return false;
        const Real inv = Real(1) / det;
        const Real tvec[3] = {-p1[0], -p1[1], -p1[2]};  // origin - P1, the origin being 0
        const Real u = dot(tvec, pvec) * inv;
        if (!(u >= 0 && u <= 1)) return false;
        cross(tvec, e1, qvec);
        const Real v = dot(ray_.dir, qvec) * inv;
        if (!(v >= 0 && u + v <= 1)) return false;
        const Real ti = dot(e2, qvec) * inv;
        if (!(ti >= tmin && ti <= tmax)) return false;
        t = ti;
        b[0] = Real(1) - u - v;
        b[1] = u;
        b[2] = v;
        return true;
    }

   private:
    RayFrame<Real> ray_;
};

}  // namespace vrc
