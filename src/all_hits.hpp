// Every surface crossing along each of an array of rays (Scene.intersect_all,
// count_intersections, contains): the wide traversal with HitPolicy::all and the exact
// watertight kernel in double, rays split among threads.
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
    int32_t facing;     ///< on an edge or vertex: +1 when the triangle faces the ray's origin, -1 else
    double t;           ///< in units of the ray's direction as given
    double b[3];        ///< weights of the triangle's points; exact zeros on its edges and vertices
    uint32_t feature[2];  ///< scene point ids of the edge or vertex hit (kNone inside the triangle)
    static constexpr uint32_t kNone = UINT32_MAX;
};

/// A ray's hits made crossings, sorted by t. The watertight kernel counts a zero edge
/// function as inside, so a ray through an edge or a vertex the triangles share meets
/// every triangle around it but crosses the surface there once: hits on the same feature
/// (edge: one exactly zero weight; vertex: two) facing the ray the same way are one
/// crossing, represented by the lowest input triangle. A ray grazing a fold (triangles
/// around the point facing it both ways) then crosses twice there, in and out, and the
/// parity that inside/outside tests rest on stays right. Features are point ids: triangles
/// must share their points.
inline void keep_crossings(std::vector<RayHit>& hits) {
    std::size_t kept = 0;
    for (const RayHit& h : hits) {
        std::size_t same = kept;
        if (h.feature[0] != RayHit::kNone)
            for (std::size_t j = 0; j < kept && same == kept; ++j)
                if (hits[j].feature[0] == h.feature[0] && hits[j].feature[1] == h.feature[1] && hits[j].facing == h.facing)
                    same = j;
        if (same == kept)
            hits[kept++] = h;
        else if (h.triangle < hits[same].triangle)
            hits[same] = h;
    }
    hits.resize(kept);
    std::sort(hits.begin(), hits.end(), [](const RayHit& x, const RayHit& y) {
        return x.t != y.t ? x.t < y.t : x.triangle < y.triangle;
    });
}

/// Takes a ray's hits from the traversal (HitPolicy::all) as RayHit records: on an edge
/// or a vertex, with the feature's point ids and the exact facing that keep_crossings groups
/// them by.
struct CrossingSink {
    const Scene* scene = nullptr;
    const Ray* ray = nullptr;
    uint64_t k = 0;
    std::vector<RayHit> hits;

    void start(std::size_t ray_index, const Ray& r) {
        k = ray_index;
        ray = &r;
        hits.clear();
    }
    void operator()(uint32_t i, double t, const double* b) {
        const uint32_t* tri = scene->triangles.data() + 3 * std::size_t(i);
        RayHit h{k, scene->prim_ids[i], 0, ray->output(t), {b[0], b[1], b[2]}, {RayHit::kNone, RayHit::kNone}};
        const int zeros = (b[0] == 0) + (b[1] == 0) + (b[2] == 0);
        if (zeros == 0) {  // inside the triangle: a crossing of its own
            hits.push_back(h);
            return;
        }
        if (zeros == 1) {  // an edge: its two points, sorted
            uint32_t e[2], m = 0;
            for (int c = 0; c < 3; ++c)
                if (b[c] != 0) e[m++] = tri[c];
            h.feature[0] = std::min(e[0], e[1]);
            h.feature[1] = std::max(e[0], e[1]);
        } else {  // a vertex
            for (int c = 0; c < 3; ++c)
                if (b[c] != 0) h.feature[0] = tri[c];
        }
        // The sign of the kernel's det is that of any nonzero edge function of a hit,
        // each the exact orientation of its edge with the ray.
        const double *pa = scene->point(tri[0]), *pb = scene->point(tri[1]), *pc = scene->point(tri[2]);
        const int facing = b[0] != 0   ? exact::orientation(pc, pb, ray->org, ray->dir)
                           : b[1] != 0 ? exact::orientation(pa, pc, ray->org, ray->dir)
                                       : exact::orientation(pb, pa, ray->org, ray->dir);
        h.facing = facing > 0 ? 1 : -1;
        hits.push_back(h);
    }
};

/// The crossings of rays 0 .. n - 1 within [tmin, tmax], each ray's sorted by t:
/// `each(part, k, hits)` is called once per ray k from worker `part`, which takes a slice
/// of the rays (slices in increasing order of the ray; within one, rays in any order: a
/// scene larger than the caches traces several at a time, trace_rays_interleaved).
template <class Each>
void for_each_crossings(const Scene& scene, const ArrayRays& rays, unsigned threads, Each&& each) {
    const std::size_t n = rays.size();
    const unsigned parts = std::max(1u, std::min<unsigned>(threads, unsigned(n / 4096 + 1)));
    const bool interleave = scene.ray_bytes() >= kInterleavedBytes;
    auto work = [&](unsigned p) {
        const std::size_t begin = n * p / parts, end = n * (p + 1) / parts;
        CrossingSink sinks[kInFlight];
        for (CrossingSink& sink : sinks) sink.scene = &scene;
        auto finish = [&](CrossingSink& sink) {
            keep_crossings(sink.hits);
            each(p, std::size_t(sink.k), sink.hits);
        };
        std::vector<std::size_t> chunk;
        for (std::size_t first = begin; first < end; first += ArrayRays::kChunk) {
            chunk.clear();
            for (std::size_t k = first; k < std::min(end, first + ArrayRays::kChunk); ++k) chunk.push_back(k);
            if (interleave && !coherent(scene, rays, chunk)) {
                trace_rays_interleaved<Watertight, double, HitPolicy::all>(
                    scene, rays, chunk, CastContext{},
                    [&](std::size_t, const Ray&, const Hit<double>&, CrossingSink* sink) { finish(*sink); }, sinks);
                continue;
            }
            for (const std::size_t k : chunk) {
                const Ray ray = rays.ray(k);
                sinks[0].start(k, ray);
                trace_ray<Watertight, double, HitPolicy::all>(scene, ray, CastContext{}, sinks[0]);
                finish(sinks[0]);
            }
        }
    };
    std::vector<std::thread> workers;
    for (unsigned p = 1; p < parts; ++p) workers.emplace_back(work, p);
    work(0);
    for (auto& w : workers) w.join();
}

}  // namespace vrc
