// Four rays, each against its own triangle, in the lanes of AVX registers: the watertight
// kernel in double precision (kernel_watertight.hpp), operation for operation, so a lane's t
// and weights are the scalar kernel's bit for bit. Camera casts use it for the pixels whose
// hit triangle is already known (TileTracer's sure hits) when the hit's depth or weights are
// asked for: one ray set-up and one set of divisions serve four pixels.
#pragma once

#include <cstdint>
#include <limits>

#include "geometry.hpp"

namespace vrc {

/// The axes of the shear, lane by lane: z the largest |d| (the first on ties), x and y the
/// next two, swapped where d_z < 0, as the scalar kernel picks them per ray. Each axis is
/// two masks (is 0, is 1), so a coordinate is chosen with two blends.
struct LaneAxes {
    Mask4 x0, x1, y0, y1, z0, z1;
    static Double4 pick(Mask4 is0, Mask4 is1, const Double4 v[3]) { return is0 ? v[0] : (is1 ? v[1] : v[2]); }
    [[nodiscard]] Double4 x(const Double4 v[3]) const { return pick(x0, x1, v); }
    [[nodiscard]] Double4 y(const Double4 v[3]) const { return pick(y0, y1, v); }
    [[nodiscard]] Double4 z(const Double4 v[3]) const { return pick(z0, z1, v); }
};

/// The same axes for every lane (a camera's neighbouring rays mostly share them): chosen by
/// index, without blends.
template <int kX, int kY, int kZ>
struct SharedAxes {
    static Double4 x(const Double4 v[3]) { return v[kX]; }
    static Double4 y(const Double4 v[3]) { return v[kY]; }
    static Double4 z(const Double4 v[3]) { return v[kZ]; }
};

/// watertight4 on the given axes.
template <class Axes>
inline unsigned watertight4_on(const Axes& axes, const Rays4& ray, const double* const corner[4][3],
                               bool cull_back_faces, double t[4], double b[4][3]) {
    using D = Double4;
    using M = Mask4;
    constexpr double kEps = std::numeric_limits<double>::epsilon();
    const auto abs = [](D v) { return D(M(v) & INT64_MAX); };
    const D* org = ray.org;
    const D dz = axes.z(ray.dir);
    const D sx = axes.x(ray.dir) / dz, sy = axes.y(ray.dir) / dz, sz = D{1, 1, 1, 1} / dz;
    // The sheared vertices, their z, and the magnitudes that bound the edge functions' errors.
    D px[3], py[3], pz[3], mx[3], my[3];
    for (int c = 0; c < 3; ++c) {
        D p[3];
        for (int k = 0; k < 3; ++k)
            p[k] = D{corner[0][c][k], corner[1][c][k], corner[2][c][k], corner[3][c][k]} - org[k];
        pz[c] = axes.z(p);
        const D x = axes.x(p), y = axes.y(p);
        px[c] = x - sx * pz[c];
        py[c] = y - sy * pz[c];
        mx[c] = abs(x) + abs(sx * pz[c]);
        my[c] = abs(y) + abs(sy * pz[c]);
    }
    const D u = px[2] * py[1] - py[2] * px[1], v = px[0] * py[2] - py[0] * px[2], w = px[1] * py[0] - py[1] * px[0];
    const D bound = D{1, 1, 1, 1} * (32 * kEps / 2);
    M ok = (abs(u) > bound * (mx[2] * my[1] + my[2] * mx[1])) & (abs(v) > bound * (mx[0] * my[2] + my[0] * mx[2])) &
           (abs(w) > bound * (mx[1] * my[0] + my[1] * mx[0]));
    ok &= ((u > 0) & (v > 0) & (w > 0)) | ((u < 0) & (v < 0) & (w < 0));
    const D det = u + v + w;
    ok &= cull_back_faces ? det > 0 : det != 0;
    const D tu = u * (sz * pz[0]), tv = v * (sz * pz[1]), tw = w * (sz * pz[2]);
    const D tt = (tu + tv + tw) / det;
    const D slack = (32 * kEps) * ((abs(tu) + abs(tv) + abs(tw)) / abs(det));
    ok &= slack <= (1e3 * kEps) * abs(tt);
    ok &= ~((ray.tmin == 0) & (abs(tt) <= slack));
    ok &= (tt >= ray.tmin) & (tt <= ray.tmax);
    const D bu = u / det, bv = v / det, bw = w / det;
    unsigned settled = 0;
    for (int l = 0; l < 4; ++l) {
        if (!ok[l]) continue;
        settled |= 1u << l;
        t[l] = tt[l];
        b[l][0] = bu[l];
        b[l][1] = bv[l];
        b[l][2] = bw[l];
    }
    return settled;
}

/// Four lanes of rays and triangles (corner[l][c] is point c of lane l's triangle). Returns
/// the mask of the lanes settled here, a hit whose t and weights are written; every other
/// lane takes a path of the scalar kernel this does not follow (an edge function within its
/// rounding bound, t from the plane, a surface through the origin, a miss) and must go to it.
inline unsigned watertight4(const Rays4& ray, const double* const corner[4][3], bool cull_back_faces, double t[4],
                            double b[4][3]) {
    using D = Double4;
    using M = Mask4;
    const auto abs = [](D v) { return D(M(v) & INT64_MAX); };
    const D* dir = ray.dir;
    const D mag[3] = {abs(dir[0]), abs(dir[1]), abs(dir[2])};
    const M over0 = mag[1] > mag[0];
    const M z2 = mag[2] > (over0 ? mag[1] : mag[0]), z1 = over0 & ~z2, z0 = ~(z1 | z2);
    const M flip = LaneAxes::pick(z0, z1, dir) < 0;
    const unsigned zb0 = lane_bits(z0), zb1 = lane_bits(z1), zb2 = lane_bits(z2), fb = lane_bits(flip);
    if ((zb0 == 15 || zb1 == 15 || zb2 == 15) && (fb == 0 || fb == 15)) {
        const int z = zb0 == 15 ? 0 : (zb1 == 15 ? 1 : 2);
        switch (z + 3 * (fb != 0)) {
            case 0: return watertight4_on(SharedAxes<1, 2, 0>{}, ray, corner, cull_back_faces, t, b);
            case 1: return watertight4_on(SharedAxes<2, 0, 1>{}, ray, corner, cull_back_faces, t, b);
            case 2: return watertight4_on(SharedAxes<0, 1, 2>{}, ray, corner, cull_back_faces, t, b);
            case 3: return watertight4_on(SharedAxes<2, 1, 0>{}, ray, corner, cull_back_faces, t, b);
            case 4: return watertight4_on(SharedAxes<0, 2, 1>{}, ray, corner, cull_back_faces, t, b);
            default: return watertight4_on(SharedAxes<1, 0, 2>{}, ray, corner, cull_back_faces, t, b);
        }
    }
    const LaneAxes axes{flip ? z1 : z2, flip ? z2 : z0, flip ? z2 : z1, flip ? z0 : z2, z0, z1};
    return watertight4_on(axes, ray, corner, cull_back_faces, t, b);
}

}  // namespace vrc
