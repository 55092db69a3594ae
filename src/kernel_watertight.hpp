// Watertight ray-triangle intersection: Woop, Benthin and Wald, "Watertight Ray/Triangle
// Intersection", JCGT 2(1), 2013.
#pragma once

#include <cmath>
#include <limits>
#include <type_traits>
#include <utility>

#include "exact_sign.hpp"
#include "geometry.hpp"
#include "kernel_common.hpp"

namespace vrc {

/// The ray is sheared so that it becomes the +z axis through the origin; the test is then
/// 2D edge functions of the sheared vertices. Each edge function depends only on the
/// edge's two vertices and the ray, and a shared edge evaluates to exactly the negated
/// value in its neighbour, so no ray passes between triangles sharing an edge.
/// Beyond the paper, an edge function whose magnitude is below its rounding-error bound
/// takes the exact sign of the 3D orientation det[C - O, B - O, d] (Shewchuk expansions),
/// so near an edge the side is decided exactly, not just consistently: the hit triangle is
/// the exact one. A zero edge value counts as inside (both neighbours report the hit: a
/// tie, never a leak). Degenerate triangles
/// (zero projected area) are never hit. With back-face culling, triangles whose normal
/// (right-hand rule over their point order) points away from the ray origin are skipped.
template <class Real>
class Watertight : public PointKernel<Watertight<Real>> {
   public:
    Watertight(const Ray& ray, const CastContext& context)
        : org_(ray.org),
          dir_(ray.dir),
          cull_(context.cull_back_faces),
          shear_(ray),
          sx_(static_cast<Real>(shear_.sx)),
          sy_(static_cast<Real>(shear_.sy)),
          sz_(static_cast<Real>(shear_.sz)) {}
    /// The ray's axes and shear (what the triangle filter works in too).
    [[nodiscard]] const Shear& shear() const { return shear_; }

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
        const int kx = shear_.kx, ky = shear_.ky, kz = shear_.kz;
        const Real ax = a[kx] - sx_ * a[kz], ay = a[ky] - sy_ * a[kz];
        const Real bx = bb[kx] - sx_ * bb[kz], by = bb[ky] - sy_ * bb[kz];
        const Real cx = c[kx] - sx_ * c[kz], cy = c[ky] - sy_ * c[kz];
        Real u = cx * by - cy * bx;
        Real v = ax * cy - ay * cx;
        Real w = bx * ay - by * ax;
        // Magnitudes of the sheared coordinates, for the error bounds of the edge functions.
        const Real mx[3] = {magnitude(a, kx, sx_), magnitude(bb, kx, sx_), magnitude(c, kx, sx_)};
        const Real my[3] = {magnitude(a, ky, sy_), magnitude(bb, ky, sy_), magnitude(c, ky, sy_)};
        bool snapped = false;  // an edge function kept its exact sign but not its size
        u = exact_if_close(u, mx[2] * my[1] + my[2] * mx[1], pc, pb, snapped);
        v = exact_if_close(v, mx[0] * my[2] + my[0] * mx[2], pa, pc, snapped);
        w = exact_if_close(w, mx[1] * my[0] + my[1] * mx[0], pb, pa, snapped);
        if ((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0)) return false;
        const Real det = u + v + w;  // > 0 when the triangle faces the ray origin
        if (det == 0 || (cull_ && det < 0)) return false;
        const Real az = sz_ * a[kz], bz = sz_ * bb[kz], cz = sz_ * c[kz];
        const Real tu = u * az, tv = v * bz, tw = w * cz;
        double tt = static_cast<double>((tu + tv + tw) / det);
        // Rounding bound on tt: it grows as the terms cancel (a surface through the origin).
        double slack = 32 * double(std::numeric_limits<Real>::epsilon()) *
                       double((std::fabs(tu) + std::fabs(tv) + std::fabs(tw)) / std::fabs(det));
        // Rare: when t kept fewer than about three good digits, or when an edge function's
        // size was lost (its sign settled exactly), which would snap t to a vertex's depth.
        if (snapped || !(slack <= 1e3 * double(std::numeric_limits<Real>::epsilon()) * std::fabs(tt)))
            plane_distance(pa, pb, pc, tt, slack);
        if (tmin == 0 && std::fabs(tt) <= slack) {
            // Is the plane in front of the origin or behind it? Within rounding of 0 (a
            // surface through the eye) the exact orientation of the origin decides:
            // t = det[A, B, C] / d.n exactly, and this kernel's det has the sign of -d.n.
            // Exactly on the plane (a ray leaving a vertex or edge), the ray meets the
            // plane at its origin alone: t = 0, whatever the ill-conditioned quotient says.
            const double volume = exact::volume(pa, pb, pc, org_);
            if (volume * (det > 0 ? -1 : 1) < 0) return false;
            tt = volume == 0 ? 0.0 : std::max(tt, 0.0);
        }
        if (!(tt >= tmin && tt <= tmax)) return false;
        t = tt;
        // Divisions, not a reciprocal: det may be as small as an exact-sign stand-in, whose
        // reciprocal would overflow.
        b[0] = u / det;
        b[1] = v / det;
        b[2] = w / det;
        return true;
    }

   private:
    /// t from the triangle's plane, n.(A) / n.d in double with A = pa - O: when the sheared
    /// terms cancel (the origin near the plane, or all edge functions tiny) this is the
    /// better conditioned form. Sets t and its rounding bound.
    void plane_distance(const double* pa, const double* pb, const double* pc, double& t, double& slack) const {
        double a[3], b[3], c[3], e1[3], e2[3], n[3];
        relative(pa, org_, a);
        relative(pb, org_, b);
        relative(pc, org_, c);
        sub(b, a, e1);
        sub(c, a, e2);
        cross(e1, e2, n);
        const double nd = dot(n, dir_), na = dot(n, a);
        if (nd == 0) return;
        t = na / nd;
        const double norm_n = std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]);
        const double norm_a = std::fabs(a[0]) + std::fabs(a[1]) + std::fabs(a[2]);
        slack = 32 * (std::numeric_limits<double>::epsilon() / 2) * norm_n * norm_a / std::fabs(nd);
    }

    /// |p_k| + |s p_z|: bounds the sheared coordinate p_k - s p_z and scales its error.
    [[nodiscard]] Real magnitude(const Real p[3], int k, Real s) const {
        return std::fabs(p[k]) + std::fabs(s * p[shear_.kz]);
    }

    /// The edge function `e` of (p, q), or, when |e| is within its rounding-error bound,
    /// `e` with the exact sign of det[p - O, q - O, d] (a zero when exactly on the edge).
    /// Each sheared coordinate carries at most about 4 eps relative to its magnitude
    /// (rounding of p - O to Real, of the shear and of its product and difference), so
    /// |e - exact| <= ~10 eps * scale; 32 eps leaves a wide margin.
    [[nodiscard]] Real exact_if_close(Real e, Real scale, const double* p, const double* q, bool& snapped) const {
        constexpr Real kBound = 32 * std::numeric_limits<Real>::epsilon() / 2;
        if (std::fabs(e) > kBound * scale) return e;
        const int sign = sign_of_edge(p, q);
        if (sign == 0) return Real(0);
        const bool agrees = (e > 0) == (sign > 0) && e != 0;
        snapped = snapped || !agrees;
        const Real size = e != 0 ? std::fabs(e) : std::numeric_limits<Real>::denorm_min();
        return sign > 0 ? size : -size;
    }

    /// Sign of det[p - O, q - O, d]. A float kernel first tries double precision (far
    /// cheaper than the expansions, and enough for all but a sliver of rays); the exact
    /// orientation settles the rest.
    [[nodiscard]] int sign_of_edge(const double* p, const double* q) const {
        if constexpr (std::is_same_v<Real, float>) {
            double pd[3], qd[3];
            for (int k = 0; k < 3; ++k) {
                pd[k] = p[k] - org_[k];
                qd[k] = q[k] - org_[k];
            }
            const int kx = shear_.kx, ky = shear_.ky, kz = shear_.kz;
            const double sxd = shear_.sx, syd = shear_.sy;
            const double px = pd[kx] - sxd * pd[kz], py = pd[ky] - syd * pd[kz];
            const double qx = qd[kx] - sxd * qd[kz], qy = qd[ky] - syd * qd[kz];
            const double e = px * qy - py * qx;
            const double scale = (std::fabs(pd[kx]) + std::fabs(sxd * pd[kz])) * (std::fabs(qd[ky]) + std::fabs(syd * qd[kz])) +
                                 (std::fabs(pd[ky]) + std::fabs(syd * pd[kz])) * (std::fabs(qd[kx]) + std::fabs(sxd * qd[kz]));
            if (std::fabs(e) > 32 * (std::numeric_limits<double>::epsilon() / 2) * scale) return (e > 0) - (e < 0);
        }
        return exact::orientation(p, q, org_, dir_);
    }

    const double* org_;
    const double* dir_;
    bool cull_;
    Shear shear_;
    Real sx_, sy_, sz_;  // shear_'s in the kernel's precision
};

}  // namespace vrc
