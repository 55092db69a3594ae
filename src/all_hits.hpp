// Every hit along each of an array of rays (Scene.intersect_all, count_intersections,
// contains): the wide traversal with HitPolicy::all and the exact watertight kernel in
// double, rays split among threads; grouping of hits into surface crossings is the
// Python side's (vtkraycast/crossings.py).
#pragma once

#include <algorithm>
#include <cstdint>
#include <thread>
#include <vector>

#include "camera_rays.hpp"
#include "exact_sign.hpp"
#include "kernel_watertight.hpp"
#include "traverse_wide.hpp"

namespace vrc {

struct RayHit {
    uint64_t ray;
    uint32_t triangle;  ///< input triangle index
    int32_t facing;     ///< +1 when the triangle faces the ray's origin (right-hand rule), -1 else
    double t;           ///< in units of the ray's direction as given
    double b[3];        ///< weights of the triangle's points; exact zeros on its edges and vertices
};

/// Every hit of rays 0 .. n - 1 with tmin <= t <= tmax, unsorted.
inline std::vector<RayHit> all_hits(const Scene& scene, const ArrayRays& rays, unsigned threads) {
    const std::size_t n = rays.size();
    const unsigned parts = std::max(1u, std::min<unsigned>(threads, unsigned(n / 4096 + 1)));
    std::vector<std::vector<RayHit>> found(parts);
    auto work = [&](unsigned p) {
        for (std::size_t k = n * p / parts, end = n * (p + 1) / parts; k < end; ++k) {
            const Ray ray = rays.ray(k);
            auto sink = [&](uint32_t i, double t, const double* b) {
                const uint32_t* tri = scene.triangles.data() + 3 * std::size_t(i);
                const double *pa = scene.point(tri[0]), *pb = scene.point(tri[1]), *pc = scene.point(tri[2]);
                // The sign of the kernel's det is that of any nonzero edge function of a hit,
                // each the exact orientation of its edge with the ray.
                const int facing = b[0] != 0   ? exact::orientation(pc, pb, ray.org, ray.dir)
                                   : b[1] != 0 ? exact::orientation(pa, pc, ray.org, ray.dir)
                                               : exact::orientation(pb, pa, ray.org, ray.dir);
                found[p].push_back({k, scene.prim_ids[i], facing > 0 ? 1 : -1, ray.output(t), {b[0], b[1], b[2]}});
            };
            trace_ray<Watertight, double, HitPolicy::all>(scene, ray, CastContext{}, sink);
        }
    };
    std::vector<std::thread> workers;
    for (unsigned p = 1; p < parts; ++p) workers.emplace_back(work, p);
    work(0);
    for (auto& w : workers) w.join();
    std::vector<RayHit> all;
    for (auto& part : found) all.insert(all.end(), part.begin(), part.end());
    return all;
}

}  // namespace vrc
