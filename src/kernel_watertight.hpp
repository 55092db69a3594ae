// Watertight ray-triangle intersection: Woop, Benthin and Wald, "Watertight Ray/Triangle
// Intersection", JCGT 2(1), 2013.
#pragma once

#include <cmath>
#include <type_traits>
#include <utility>

#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// The ray is sheared so that it becomes the +z axis through the origin; the test is then
/// 2D edge functions of the sheared vertices. Each edge function depends only on the
/// edge's two vertices and the ray, and a shared edge evaluates to exactly the negated
/// value in its neighbour, so no ray passes between triangles sharing an edge. An edge
/// function that rounds to exactly 0 is re-evaluated in the next wider precision, for that
/// edge alone, so the rule stays a function of the edge. A zero edge value counts as
/// inside (both neighbours report the hit: a tie, never a leak). Degenerate triangles
/// (zero projected area) are never hit. With back-face culling, triangles whose normal
/// (right-hand rule over their point order) points away from the ray origin are skipped.
template <class Real>
class Watertight : public PointKernel<Watertight<Real>> {
   public:
    /// Wider type used when an edge function is exactly 0.
    using Wide = std::conditional_t<std::is_same_v<Real, float>, double, long double>;

    Watertight(const Ray& ray, const CastContext& context) : org_(ray.org), cull_(context.cull_back_faces) {
        kz_ = 0;
        for (int k = 1; k < 3; ++k)
            if (std::fabs(ray.dir[k]) > std::fabs(ray.dir[kz_])) kz_ = k;
        kx_ = (kz_ + 1) % 3;
        ky_ = (kx_ + 1) % 3;
        if (ray.dir[kz_] < 0) std::swap(kx_, ky_);  // keep the winding of the sheared triangle
        const double sx = ray.dir[kx_] / ray.dir[kz_], sy = ray.dir[ky_] / ray.dir[kz_];
        sx_ = static_cast<Real>(sx);
        sy_ = static_cast<Real>(sy);
        sz_ = static_cast<Real>(1.0 / ray.dir[kz_]);
        wsx_ = static_cast<Wide>(ray.dir[kx_]) / ray.dir[kz_];
        wsy_ = static_cast<Wide>(ray.dir[ky_]) / ray.dir[kz_];
    }

    /// Intersects triangle (pa, pb, pc). On a hit with tmin <= t <= tmax returns true and
    /// sets t (in units of the ray direction) and the weights of pa, pb, pc.
    bool operator()(const double* pa, const double* pb, const double* pc, double tmin, double tmax, double& t,
                    Real b[3]) const {
        // Vertices relative to the ray origin, subtracted in double before rounding.
        Real a[3], bb[3], c[3];
        for (int k = 0; k < 3; ++k) {
            a[k] = static_cast<Real>(pa[k] - org_[k]);
            bb[k] = static_cast<Real>(pb[k] - org_[k]);
            c[k] = static_cast<Real>(pc[k] - org_[k]);
        }
        const Real ax = a[kx_] - sx_ * a[kz_], ay = a[ky_] - sy_ * a[kz_];
        const Real bx = bb[kx_] - sx_ * bb[kz_], by = bb[ky_] - sy_ * bb[kz_];
        const Real cx = c[kx_] - sx_ * c[kz_], cy = c[ky_] - sy_ * c[kz_];
        Real u = cx * by - cy * bx;
        Real v = ax * cy - ay * cx;
        Real w = bx * ay - by * ax;
        if (u == 0) u = static_cast<Real>(wide_edge(pc, pb));
        if (v == 0) v = static_cast<Real>(wide_edge(pa, pc));
        if (w == 0) w = static_cast<Real>(wide_edge(pb, pa));
        if ((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0)) return false;
        const Real det = u + v + w;  // > 0 when the triangle faces the ray origin
        if (det == 0 || (cull_ && det < 0)) return false;
        const Real az = sz_ * a[kz_], bz = sz_ * bb[kz_], cz = sz_ * c[kz_];
        const double tt = static_cast<double>((u * az + v * bz + w * cz) / det);
        if (!(tt >= tmin && tt <= tmax)) return false;
        t = tt;
        const Real inv = Real(1) / det;
        b[0] = u * inv;
        b[1] = v * inv;
        b[2] = w * inv;
        return true;
    }

   private:
    /// Edge function of (p, q) (the 2D cross product of the sheared p and q) in Wide.
    [[nodiscard]] Wide wide_edge(const double* p, const double* q) const {
        Wide pw[3], qw[3];
        for (int k = 0; k < 3; ++k) {
            pw[k] = static_cast<Wide>(p[k]) - org_[k];
            qw[k] = static_cast<Wide>(q[k]) - org_[k];
        }
        const Wide px = pw[kx_] - wsx_ * pw[kz_], py = pw[ky_] - wsy_ * pw[kz_];
        const Wide qx = qw[kx_] - wsx_ * qw[kz_], qy = qw[ky_] - wsy_ * qw[kz_];
        return px * qy - py * qx;
    }

    const double* org_;
    bool cull_;
    int kx_, ky_, kz_;
    Real sx_, sy_, sz_;
    Wide wsx_, wsy_;
};

}  // namespace vrc
