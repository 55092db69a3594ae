// Flat bounding volume hierarchy over a triangle mesh: the data, shared by the builder
// (bvh_build.cpp) and the traversal (traverse.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "exact_sign.hpp"
#include "geometry.hpp"
#include "memory.hpp"

namespace vrc {

/// One node, 32 bytes. Inner nodes have `count == 0` and their two children at
/// `index` and `index + 1`; leaves hold triangles `index .. index + count - 1`.
struct Node {
    Box box;
    uint32_t index;
    uint32_t count;
    [[nodiscard]] bool is_leaf() const { return count != 0; }
};
static_assert(sizeof(Node) == 32, "nodes are meant to be 32 bytes");

/// Triangles, in BVH leaf order, and the hierarchy over them. Owns copies of its input so
/// that a mesh modified after (or during) a cast cannot change a result.
struct Scene {
    std::vector<double> points;       ///< (n_points, 3) world coordinates, in order of first use
    std::vector<uint32_t> triangles;  ///< (n_triangles, 3) point indices, in leaf order
    std::vector<uint32_t> prim_ids;   ///< leaf-order position -> input triangle index
    std::vector<Node> nodes;          ///< nodes[0] is the root; empty when there are no triangles
    /// Each leaf's points, once each: node i's are leaf_points[leaf_offsets[i] ..
    /// leaf_offsets[i + 1]) (none for an inner node). A camera cast frames a leaf from them:
    /// under half its triangles' point references (2.0 M of 4.5 M on the frog contour).
    std::vector<uint32_t> leaf_offsets, leaf_points;
    /// Boxes are stored relative to this point (the centre of the triangles' bounding box), so
    /// their single precision resolves the scene's own size, wherever it lies in the world.
    double anchor[3] = {0, 0, 0};
    Box bounds;                       ///< box of all triangles, relative to `anchor` (rounded outward)
    double sphere_center[3] = {0, 0, 0};  ///< the seed's bounding sphere: box centre...
    double sphere_radius = -1;            ///< ...and largest point distance to it (-1: empty)
    /// Working memory of camera casts, kept between them (shared: a Scene stays movable).
    std::shared_ptr<ScratchPool> scratch = std::make_shared<ScratchPool>();

    [[nodiscard]] std::size_t n_triangles() const { return prim_ids.size(); }
    /// False for a flat scene (triangles but no hierarchy: one camera cast's worth).
    [[nodiscard]] bool has_bvh() const { return !nodes.empty() || prim_ids.empty(); }
    [[nodiscard]] const double* point(uint32_t i) const { return points.data() + 3 * std::size_t(i); }
    /// Asks the cache for triangle i's points (leaf order), ahead of a kernel reading them.
    void prefetch_points(uint32_t i) const {
        for (int k = 0; k < 3; ++k) __builtin_prefetch(point(triangles[3 * std::size_t(i) + k]));
    }
    /// Bytes held by the structure and the per-triangle data (points included), and the
    /// working memory kept from camera casts.
    [[nodiscard]] std::size_t memory_bytes() const {
        return points.size() * sizeof(double) + triangles.size() * sizeof(uint32_t) +
               prim_ids.size() * sizeof(uint32_t) + nodes.size() * sizeof(Node) +
               (leaf_offsets.size() + leaf_points.size()) * sizeof(uint32_t) + scratch->bytes();
    }
};

/// Builds a scene with the binned surface area heuristic (Wald 2007, "On fast
/// construction of SAH-based bounding volume hierarchies"), subtrees built in parallel on
/// up to `threads` threads. `points` is (n_points, 3), `triangles` (n_triangles, 3) with
/// indices already checked to be < n_points.
[[nodiscard]] Scene build_scene(const double* points, std::size_t n_points, const uint32_t* triangles,
                                std::size_t n_triangles, unsigned threads);

/// Sets the scene's anchor (the centre of the triangles' bounding box), its bounds relative
/// to the anchor (rounded outward) and the seed's bounding sphere around it.
void frame_scene(Scene& scene, const double* points, const uint32_t* triangles, std::size_t n_triangles);

/// Copies into the scene the points its triangles use, in the order they first use them,
/// and renumbers the triangles: neighbouring triangles (in leaf order, or a mesh's own order)
/// then read neighbouring points. Unused points are dropped.
void order_points(Scene& scene, const double* points, std::size_t n_points);

/// Lists each leaf's points (leaf_offsets, leaf_points), once the points are in order.
void list_leaf_points(Scene& scene);

/// The same scene without a hierarchy (triangles in input order): all a single camera cast
/// needs, as its triangles are binned to the image's tiles instead (bin_triangles.hpp).
[[nodiscard]] Scene flat_scene(const double* points, std::size_t n_points, const uint32_t* triangles,
                               std::size_t n_triangles);

}  // namespace vrc
