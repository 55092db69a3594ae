// The tile renderer: rays in tiles spread over worker threads, closest hits written into
// caller-owned arrays.
#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include <type_traits>

#include "traverse.hpp"
#include "traverse_wide.hpp"
#include "bin_triangles.hpp"
#include "outputs.hpp"
#include "traverse_bundle.hpp"
#include "traverse_tile.hpp"

namespace vrc {

/// Called from the calling thread with (tiles done, tiles total) as the cast starts, then
/// about every 50 ms; returning false aborts the cast between tiles.
using Poll = std::function<bool(std::size_t, std::size_t)>;

/// Every worker waits here until all have arrived (spinning with yields: it separates
/// phases of a cast that each take milliseconds).
class Barrier {
   public:
    explicit Barrier(unsigned n) : n_(n) {}
    void wait() {
        const unsigned generation = generation_.load();
        if (arrived_.fetch_add(1) + 1 == n_) {
            arrived_.store(0);
            generation_.fetch_add(1);
        } else {
            while (generation_.load() == generation) std::this_thread::yield();
        }
    }

   private:
    unsigned n_;
    std::atomic<unsigned> arrived_{0}, generation_{0};
};

/// What camera rays share across tiles: the projected scene, and on a flat scene (no BVH)
/// the triangles binned to tiles. Prepared by all workers together (`prepare`).
struct CameraCast {
    CameraCast(const Scene& scene, const CameraRays& rays, unsigned workers) : projected(scene, rays), barrier(workers) {
        if (!scene.has_bvh()) bins.emplace(scene, rays, projected, workers);
    }
    /// Whether camera rays of this size go through tiles: the image rectangles hold 16-bit
    /// pixel indices. (Larger images through a BVH are traced ray by ray.)
    static bool fits(const CameraSpec& c) { return c.nx <= ImageRect::kMaxPixels && c.ny <= ImageRect::kMaxPixels; }
    /// Whether the camera tree's links (nodes and triangles) fit the projected nodes' 27
    /// bits (else ray by ray).
    static bool fits(const Scene& scene) {
        return scene.camera.nodes.size() < ProjectedNode::kMaxIndex && scene.n_triangles() < ProjectedNode::kMaxIndex;
    }
    /// Whether the preparation (every point and camera-tree node, once per camera) pays off
    /// through a BVH: not when few pixels may see a large scene, which then go ray by ray.
    /// What a pixel is worth in prepared elements, from alternated runs (compare_builds.py
    /// with the choice forced, 2 threads, noisy): the frog contour (0.9 M points and nodes,
    /// in a view that frames it, covering an eighth of it) is 1.47x faster ray by ray at
    /// 128x128, 1.09x at 192x192, even at 224x224, and 1.19x slower at 256x256; a bumpy
    /// sphere of 330 k triangles (0.2 M) filling the frame is 1.11x slower ray by ray at
    /// 64x64 and 1.8x at 128x128. A pixel that may see the scene (a bound on those that
    /// do) is worth more when more do: 32 lies between the two, each about 10 % off near
    /// its crossover.
    static constexpr std::size_t kElementsPerPixel = 32;
    static bool pays(const Scene& scene, const CameraRays& rays) {
        // (a frame nothing can see stays: the camera path prepares nothing for it and
        // writes its misses without making rays)
        const std::size_t pixels = rays.pixels_may_hit();
        return !scene.has_bvh() || pixels == 0 || kElementsPerPixel * pixels >= scene.points.size() / 3 + scene.camera.nodes.size();
    }
    /// Worker w's share of the preparation (none when no pixel may see the scene: every
    /// tile is then a miss).
    void prepare(unsigned w, const CameraRays& rays) {
        if (!rays.may_hit()) return;
        if (!bins) {
            projected.project_and_frame();
            barrier.wait();
            if (w == 0) projected.frame_top();
            barrier.wait();
            return;
        }
        projected.project();
        barrier.wait();
        bins->bin(w);
        barrier.wait();
    }
    ProjectedScene projected;
    std::optional<TriangleBins> bins;
    Barrier barrier;
};

/// Casts every ray of `rays`, tiles shared among `threads` workers, through the BVH (or,
/// with kBruteForce, the seed's sphere-box-every-triangle method), optionally skipping
/// triangles that face away from the ray. Returns false when
/// `poll` aborted the cast (outputs then partly written).
template <template <class> class Kernel, class Real, bool kBruteForce, class Rays>
bool render(const Scene& scene, const Rays& rays, const Outputs<Real>& out, const CastContext& context,
            unsigned threads, const Poll& poll) {
    const std::size_t n_tiles = rays.n_tiles();
    std::atomic<std::size_t> next{0}, done{0};
    std::atomic<bool> abort{false};
    std::mutex mutex;
    std::condition_variable finished;

    // Camera rays go a tile at a time (traverse_tile.hpp), through the BVH or, on a flat
    // scene, through the triangles binned to the tile (bin_triangles.hpp); such tiles store
    // their pixels row by row, in the outputs' order, as do arrays' rays traced one by one:
    // streaming stores serve them when the outputs outgrow the caches (smaller ones are
    // best left there for what reads them next). Written through the cache, they would
    // also push a scene's nodes and triangles out of the L2 cache, where a scene of 20 k
    // triangles fits, leaving its rays to wait for them.
    constexpr bool kTiles = std::is_same_v<Rays, CameraRays> && !kBruteForce;
    bool camera_tiles = false;
    if constexpr (kTiles)
        camera_tiles = CameraCast::fits(rays.spec()) && CameraCast::fits(scene) && CameraCast::pays(scene, rays);
    const bool interleave = !kBruteForce && scene.ray_bytes() >= kInterleavedBytes;
    const bool in_order = camera_tiles || (std::is_same_v<Rays, ArrayRays> && !interleave);
    constexpr std::size_t kStreamedBytes = std::size_t(16) << 20;
    const OutputWriter<Real> store(scene, out, in_order && rays.size() * out.bytes_per_ray() >= kStreamedBytes);
    auto tile_done = [&] {
        if (done.fetch_add(1) + 1 == n_tiles) {
            std::lock_guard<std::mutex> lock(mutex);
            finished.notify_all();
        }
    };
    // `by_ray` (a worker's): whether a tile of coherent rays goes one ray after another or
    // several in flight (incoherent ones always go several in flight).
    auto trace_rays = [&](std::size_t tile, CostChooser& by_ray, InFlightChooser& in_flight) {
        // The seed's bounding test, a whole tile at a time: tiles that cannot see the
        // scene are misses without a single ray made.
        const bool may_hit = rays.tile_may_hit(tile);
        std::vector<std::size_t> tile_rays;
        if (may_hit && interleave) rays.for_each_in_tile(tile, [&](std::size_t k) { tile_rays.push_back(k); });
        unsigned nodes = 0;  // (the chooser's unit of work: rays' costs vary far more)
        const auto interleaved = [&] {
            const DeferredStore<OutputWriter<Real>> take{store};
            NoSink* no_sinks = nullptr;
            in_flight.run(nodes, [&](int searches) {
                if (context.any_hit)
                    trace_rays_interleaved<Kernel, Real, HitPolicy::any>(scene, rays, tile_rays, context, take, no_sinks, &nodes,
                                                                         searches);
                else
                    trace_rays_interleaved<Kernel, Real, HitPolicy::closest>(scene, rays, tile_rays, context, take, no_sinks,
                                                                             &nodes, searches);
            });
        };
        if (may_hit && interleave && !coherent(scene, rays, tile_rays)) return interleaved();
        unsigned* counted = interleave ? &nodes : nullptr;  // (only the chooser reads them)
        const auto one_by_one = [&] {
            rays.for_each_in_tile(tile, [&](std::size_t k) {
                if (!may_hit) return store(k, Ray{}, Hit<Real>{});  // (store reads the ray of hits only)
                // (the input rays asked for eight ahead: for random rays through a scene in
                // the caches, the hardware's prefetchers alone do not bring them in time)
                if constexpr (std::is_same_v<Rays, ArrayRays>) {
                    if (k + 8 < rays.size()) rays.prefetch(k + 8);
                }
                const Ray ray = rays.ray(k);
                constexpr HitPolicy kAny = HitPolicy::any;
                if (context.any_hit)
                    store(k, ray,
                          kBruteForce ? brute_force_hit<Kernel, Real, kAny>(scene, ray, context)
                                      : trace_ray<Kernel, Real, kAny>(scene, ray, context, NoSink{}, counted));
                else
                    store(k, ray,
                          kBruteForce ? brute_force_hit<Kernel, Real>(scene, ray, context)
                                      : trace_ray<Kernel, Real>(scene, ray, context, NoSink{}, counted));
            });
        };
        if (!may_hit || !interleave) return one_by_one();
        by_ray.run([&](bool several) {
            several ? interleaved() : one_by_one();
            return double(nodes);
        });
    };
    const unsigned n_workers = std::max(1u, std::min<unsigned>(threads, unsigned(std::max<std::size_t>(n_tiles, 1))));
    std::optional<std::conditional_t<kTiles, CameraCast, int>> camera;
    if constexpr (kTiles) {
        if (camera_tiles) camera.emplace(scene, rays, n_workers);
    }
    // A sweep's tiles go as bundles (traverse_bundle.hpp) where the kernel's hits are exact
    // (its culling by projection takes a hit to be a point of the triangle).
    constexpr bool kBundles = std::is_same_v<Rays, SweepRays> && !kBruteForce && std::is_same_v<Kernel<Real>, Watertight<double>>;
    auto trace_tiles = [&](unsigned w) {
        if constexpr (kBundles) {
            if (!context.any_hit) {
                auto tracer = std::make_unique<BundleTracer<Kernel, Real>>(scene, rays, context);
                for (std::size_t tile; !abort.load(std::memory_order_relaxed) && (tile = next.fetch_add(1)) < n_tiles;) {
                    tracer->trace(tile, store);
                    tile_done();
                }
                return;
            }
        }
        if constexpr (kTiles) {
            if (camera) {
                camera->prepare(w, rays);
                TileTracer<Kernel, Real> tracer(scene, rays, camera->projected, context, !out.needs_hit_point(),
                                                out.has_point_fields());
                for (std::size_t tile; !abort.load(std::memory_order_relaxed) && (tile = next.fetch_add(1)) < n_tiles;) {
                    if (camera->bins && rays.tile_may_hit(tile))
                        tracer.trace_bin(tile, *camera->bins, store);
                    else
                        tracer.trace(tile, store);
                    tile_done();
                }
                return;
            }
        }
        CostChooser by_ray;
        InFlightChooser in_flight;
        for (std::size_t tile; !abort.load(std::memory_order_relaxed) && (tile = next.fetch_add(1)) < n_tiles;) {
            trace_rays(tile, by_ray, in_flight);
            tile_done();
        }
    };
    const auto work = [&](unsigned w) {
        trace_tiles(w);
        store.fence();
    };
    if (poll && !poll(0, n_tiles)) return false;  // so even a cast too short for a second call can be stopped
    if (n_tiles <= 1) {  // (a thread started and joined would cost more than a small batch's rays)
        work(0);
        return true;
    }
    std::vector<std::thread> workers;
    for (unsigned w = 0; w < n_workers; ++w) workers.emplace_back(work, w);
    {
        std::unique_lock<std::mutex> lock(mutex);
        while (done.load() < n_tiles && !abort.load()) {
            finished.wait_for(lock, std::chrono::milliseconds(50));
            if (poll && done.load() < n_tiles) {
                lock.unlock();
                if (!poll(done.load(), n_tiles)) abort = true;
                lock.lock();
            }
        }
    }
    for (auto& t : workers) t.join();
    return !abort.load();
}

}  // namespace vrc
