// The seed lecture's Strategy I: ray-plane intersection, then an inside test by the
// orientation of three sub-triangles.
#pragma once

#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// With the ray origin at 0: n = (P2 - P1) x (P3 - P1); t = n.P1 / n.d, rejected when
/// n.d == 0 (the ray is parallel to the plane) or t is outside [tmin, tmax]. The point
/// Pi = t d is inside when the normals of (P1, P2, Pi), (P2, P3, Pi) and (P3, P1, Pi) all
/// point along n (n_i . n > 0, strictly, as in the lecture: a point exactly on an edge is
/// outside both triangles sharing it, and rounding can put a point outside both, so the
/// test is not watertight). The weights are the sub-triangle areas over the whole.
template <class Real>
class SeedPlane : public PointKernel<SeedPlane<Real>> {
   public:
    SeedPlane(const Ray& ray, const CastContext& context) : ray_(ray, context) {}

    bool operator()(const double* pa, const double* pb, const double* pc, double tmin, double tmax, double& t,
                    Real b[3]) const {
        Real p1[3], p2[3], p3[3], e1[3], e2[3], n[3];
        relative(pa, ray_.org, p1);
        relative(pb, ray_.org, p2);
        relative(pc, ray_.org, p3);
        sub(p2, p1, e1);
        sub(p3, p1, e2);
        cross(e1, e2, n);
        const Real nd = dot(n, ray_.dir);
        if (nd == 0 || (ray_.cull && nd > 0)) return false;  // tangent ray, or a back face
        const Real ti = dot(n, p1) / nd;
        if (!(ti >= tmin && ti <= tmax)) return false;
        const Real pi[3] = {ti * ray_.dir[0], ti * ray_.dir[1], ti * ray_.dir[2]};
        // Twice the area (times |n|) of (P1, P2, Pi), (P2, P3, Pi), (P3, P1, Pi): the
        // weights of P3, P1 and P2.
        const Real w3 = sub_triangle(p1, p2, pi, n), w1 = sub_triangle(p2, p3, pi, n), w2 = sub_triangle(p3, p1, pi, n);
        if (!(w1 > 0 && w2 > 0 && w3 > 0)) return false;
        const Real sum = w1 + w2 + w3;  // divided by, not inverted: a tiny sum would overflow
        t = ti;
        b[0] = w1 / sum;
        b[1] = w2 / sum;
        b[2] = w3 / sum;
        return true;
    }

   private:
    /// n_i . n for the sub-triangle (p, q, pi), n_i = (q - p) x (pi - p).
    static Real sub_triangle(const Real p[3], const Real q[3], const Real pi[3], const Real n[3]) {
        Real a[3], c[3], ni[3];
        sub(q, p, a);
        sub(pi, p, c);
        cross(a, c, ni);
        return dot(ni, n);
    }

    RayFrame<Real> ray_;
};

}  // namespace vrc
