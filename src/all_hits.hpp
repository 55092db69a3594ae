// Every surface crossing along each of an array of rays (Scene.intersect_all,
// count_intersections, contains): the wide traversal with HitPolicy::all and the exact
// watertight kernel in double, rays split among threads.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>

#include "camera_rays.hpp"
#include "exact_sign.hpp"
#include "kernel_watertight.hpp"
#include "traverse_wide.hpp"

namespace vrc {

struct RayHit {
    uint64_t ray;
    uint32_t triangle;  ///< input triangle index (leaf order until CrossingSink::finish)
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
    if (hits.size() < 2) return;
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
        // (the input index asked for now and read in finish: read here, a scene beyond the
        // caches held every search in flight at each hit until it came)
        prefetch_line(scene->prim_ids.data() + i);
        RayHit h{k, i, 0, ray->output(t), {b[0], b[1], b[2]}, {RayHit::kNone, RayHit::kNone}};
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
    /// The ray's hits with their input triangle indices, made crossings (keep_crossings).
    void finish() {
        for (RayHit& h : hits) h.triangle = scene->prim_ids[h.triangle];
        keep_crossings(hits);
    }
};

/// The crossings of rays 0 .. n - 1 within [tmin, tmax], each ray's sorted by t:
/// `each(part, k, hits)` is called once per ray k from worker `part`. Workers take chunks
/// of consecutive rays as they finish the last (a shared machine slows one core or the
/// other: halves fixed in advance made the call wait for the slower), and within a chunk
/// rays finish in any order (a scene larger than the caches traces several at a time,
/// trace_rays_interleaved).
template <class Each>
void for_each_crossings(const Scene& scene, const ArrayRays& rays, unsigned threads, Each&& each) {
    const std::size_t n = rays.size();
    const unsigned parts = std::max(1u, std::min<unsigned>(threads, unsigned(n / 4096 + 1)));
    const bool interleave = scene.ray_bytes() >= kInterleavedBytes;
    std::atomic<std::size_t> next_chunk{0};
    auto work = [&](unsigned p) {
        CrossingSink sinks[kInFlight];
        for (CrossingSink& sink : sinks) sink.scene = &scene;
        auto finish = [&](CrossingSink& sink) {
            sink.finish();
            each(p, std::size_t(sink.k), sink.hits);
        };
        std::vector<std::size_t> chunk;
        InFlightChooser in_flight;
        unsigned nodes = 0;  // (the chooser's unit of work)
        for (std::size_t first; (first = next_chunk.fetch_add(1) * ArrayRays::kChunk) < n;) {
            chunk.clear();
            for (std::size_t k = first; k < std::min(n, first + ArrayRays::kChunk); ++k) chunk.push_back(k);
            if (interleave && !coherent(scene, rays, chunk)) {
                in_flight.run(nodes, [&](int searches) {
                    trace_rays_interleaved<Watertight, double, HitPolicy::all>(
                        scene, rays, chunk, CastContext{},
                        [&](std::size_t, const Ray&, const Hit<double>&, CrossingSink* sink) { finish(*sink); }, sinks,
                        &nodes, searches);
                });
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

/// Every crossing of rays 0 .. n - 1 in flat arrays, by ray then t: ray k's are rows
/// splits[k] .. splits[k + 1] - 1 (Open3D's list_intersections layout).
struct CrossingList {
    std::size_t rows = 0;
    std::unique_ptr<int64_t[]> splits, ray, triangle;  ///< (n + 1), rows, rows
    std::unique_ptr<double[]> t, b;                      ///< rows, 3 rows
};

/// list_crossings' working memory, kept from call to call: grown fresh, the workers' hit
/// buffers fault in a page per 4 KiB, about 7 % of the time of listing 200,000 random
/// rays' crossings on a 20 k-triangle scene. One call at a time uses it (others make
/// their own); a call that grew it past kKeptBytes gives it back (about a million
/// crossings).
struct CrossingScratch {
    std::vector<std::vector<RayHit>> found;  ///< per worker, its rays' crossings as found
    std::vector<uint32_t> part;              ///< per ray, its worker
    std::vector<std::size_t> first;          ///< per ray, the place of its first crossing in found[part]
    static constexpr std::size_t kKeptBytes = std::size_t(64) << 20;

    std::size_t bytes() const {
        std::size_t total = part.capacity() * sizeof(uint32_t) + first.capacity() * sizeof(std::size_t);
        for (const auto& f : found) total += f.capacity() * sizeof(RayHit);
        return total;
    }
};

/// The workers keep their rays' crossings as found (rays finish in any order), with each
/// ray's place among them; the counts' running sum then places every ray's rows, and the
/// rows are copied there in parallel: no sort.
inline CrossingList list_crossings(const Scene& scene, const ArrayRays& rays, unsigned threads) {
    static std::mutex kept_lock;
    static CrossingScratch kept;
    std::unique_lock<std::mutex> lock(kept_lock, std::try_to_lock);
    CrossingScratch own;
    CrossingScratch& scratch = lock.owns_lock() ? kept : own;
    const std::size_t n = rays.size();
    auto& found = scratch.found;
    found.resize(std::max<std::size_t>(found.size(), std::max(1u, threads)));
    for (auto& f : found) f.clear();
    scratch.part.resize(n);
    scratch.first.resize(n);
    uint32_t* part = scratch.part.data();
    std::size_t* first = scratch.first.data();
    CrossingList list;
    list.splits.reset(new int64_t[n + 1]);
    int64_t* count = list.splits.get() + 1;  // (made the running sum below)
    for_each_crossings(scene, rays, threads, [&](unsigned p, std::size_t k, const std::vector<RayHit>& hits) {
        count[k] = int64_t(hits.size());
        part[k] = p;
        first[k] = found[p].size();
        found[p].insert(found[p].end(), hits.begin(), hits.end());
    });
    list.splits[0] = 0;
    for (std::size_t k = 0; k < n; ++k) list.splits[k + 1] += list.splits[k];
    list.rows = std::size_t(list.splits[n]);
    list.ray.reset(new int64_t[list.rows]);
    list.triangle.reset(new int64_t[list.rows]);
    list.t.reset(new double[list.rows]);
    list.b.reset(new double[3 * list.rows]);
    auto copy = [&](std::size_t begin, std::size_t end) {
        for (std::size_t k = begin; k < end; ++k) {
            const RayHit* h = found[part[k]].data() + first[k];
            for (std::size_t row = std::size_t(list.splits[k]), last = std::size_t(list.splits[k + 1]); row < last;
                 ++row, ++h) {
                list.ray[row] = int64_t(k);
                list.triangle[row] = h->triangle;
                list.t[row] = h->t;
                for (int c = 0; c < 3; ++c) list.b[3 * row + c] = h->b[c] + 0.0;  // (no -0.0)
            }
        }
    };
    const unsigned parts = std::max(1u, std::min<unsigned>(threads, unsigned(list.rows / 65536 + 1)));
    std::vector<std::thread> workers;
    for (unsigned p = 1; p < parts; ++p) workers.emplace_back(copy, n * p / parts, n * (p + 1) / parts);
    copy(0, n / parts);
    for (auto& w : workers) w.join();
    if (scratch.bytes() > CrossingScratch::kKeptBytes) scratch = CrossingScratch{};
    return list;
}

}  // namespace vrc
