// Flat bounding volume hierarchy over a triangle mesh: the data, shared by the builder
// (bvh_build.cpp) and the traversal (traverse.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <vector>

#include "exact_sign.hpp"
#include "geometry.hpp"
#include "memory.hpp"
#include "wide_bvh.hpp"

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

/// The BVH as a camera cast's tiles go through it (traverse_tile.hpp): every subtree of at
/// most kMaxLeaf triangles is one leaf. A tile culls a triangle with a few integer compares
/// on its image rectangle, so a node visit (a dependent load, mostly a cache miss) costs
/// it more than a triangle, where a single ray's triangle test is a whole kernel (the SAH
/// building such leaves made the frog's camera casts faster and its rays cast one by one
/// 1.26x slower: this tree serves the first and leaves the second alone). Leaves this
/// large because a view whose triangles are smaller than its pixels (the terrain's framed
/// view, 15 per covered pixel) visits every leaf, each visit waiting on a node's links;
/// larger still cost views that crop a model (the frog's full view). An eighth of the
/// BVH's nodes on the frog, so an eighth of the per-camera framing.
struct CameraTree {
    static constexpr uint32_t kMaxLeaf = 63;
    /// As Node's links: the first child (the second follows it), or the first triangle and
    /// the count of a leaf (0 for an inner node). Laid out as the BVH is (sibling pairs,
    /// depth first).
    struct Link {
        uint32_t index, count;
    };
    std::vector<Link> nodes;
    /// Each leaf's points, once each: node i's are leaf_points[leaf_offsets[i] ..
    /// leaf_offsets[i + 1]) (none for an inner node). A camera cast frames a leaf from them:
    /// 1.3 M of the triangles' 4.5 M point references on the frog contour.
    std::vector<uint32_t> leaf_offsets, leaf_points;
    /// Per node, 1 + the largest point index its triangles and all before them use: points
    /// are numbered by first use, so a run of nodes first uses points [the previous node's
    /// point_end, its last node's point_end). A cast projects and frames a run at a time.
    std::vector<uint32_t> point_end;
    /// The tree cut into subtrees, in the triangles' order, that a cast's workers project
    /// and frame one at a time (ProjectedScene::project_and_frame); `top` holds the nodes
    /// above them, parents before children. A camera that cannot see a subtree's box frames
    /// none of its nodes and projects, of the points it uses first, only those that later
    /// subtrees' leaves also use (`shared`).
    struct Subtree {
        uint32_t root, first, end;          ///< its root, then its other nodes [first, end) (none for a leaf)
        uint32_t shared_begin, shared_end;  ///< shared[shared_begin, shared_end): see above
        Box box;                            ///< around its triangles, relative to the scene's anchor
    };
    static constexpr std::size_t kSubtrees = 64;  // enough to balance a few dozen workers
    std::vector<Subtree> subtrees;
    std::vector<uint32_t> top, shared;
};

/// Triangles, in BVH leaf order, and the hierarchy over them. Owns copies of its input so
/// that a mesh modified after (or during) a cast cannot change a result.
struct Scene {
    std::vector<double> points;       ///< (n_points, 3) world coordinates, in order of first use
    std::vector<uint32_t> triangles;  ///< (n_triangles, 3) point indices, in leaf order
    std::vector<uint32_t> prim_ids;   ///< leaf-order position -> input triangle index
    /// Scene point -> input point: a hit's corners as rows of the mesh's point arrays, read
    /// through the triangle the kernel has just loaded and a table in the same order.
    std::vector<uint32_t> point_ids;
    std::size_t input_points = 0;     ///< points of the input mesh (point fields have a row each)
    /// The binary BVH, nodes[0] the root, while the scene is built: the camera tree and the
    /// wide nodes are made from it, then it is freed (nothing casts through it).
    std::vector<Node> nodes;
    std::size_t binary_nodes = 0;     ///< how many it had (0 when there are no triangles)
    CameraTree camera;                ///< the hierarchy as camera casts go through it
    std::vector<WideNode> wide;       ///< the hierarchy as single rays go through it
    /// Its leaves' triangles as single rays' filter reads them: LeafBlocks, at the word
    /// offsets the wide nodes give, and eight bytes of padding.
    std::vector<std::byte> leaf_bytes;
    /// The leaves' coordinates are scaled by this power of two (0: the scene's coordinates
    /// lie beyond what the filter's bounds hold, and it lets every triangle through).
    double leaf_scale = 1;
    /// Whether single rays ask for a leaf's point indices before its filter runs
    /// (kPrefetchedIndexBytes; set with the wide nodes, not worked out at every leaf).
    bool indices_prefetched = false;
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
    [[nodiscard]] bool has_bvh() const { return binary_nodes > 0 || prim_ids.empty(); }
    [[nodiscard]] const double* point(uint32_t i) const { return points.data() + 3 * std::size_t(i); }
    /// The block of the leaf a wide node's lane gives as `child`.
    [[nodiscard]] const LeafBlock& leaf(uint32_t child) const {
        return *std::launder(reinterpret_cast<const LeafBlock*>(leaf_bytes.data() + 4 * std::size_t(child)));
    }
    /// Row of the mesh's point arrays of corner c of triangle i (leaf order).
    [[nodiscard]] uint32_t input_point(uint32_t i, int c) const { return point_ids[triangles[3 * std::size_t(i) + c]]; }
    /// Asks the cache for triangle i's points (leaf order), ahead of a kernel reading them.
    void prefetch_points(uint32_t i) const {
        for (int k = 0; k < 3; ++k) prefetch_line(point(triangles[3 * std::size_t(i) + k]));
    }
    /// Bytes single rays read: the wide nodes, the triangles and their points.
    [[nodiscard]] std::size_t ray_bytes() const {
        return wide.size() * sizeof(WideNode) + leaf_bytes.size() + triangles.size() * sizeof(uint32_t) +
               points.size() * sizeof(double);
    }
    /// Bytes held by the structure and the per-triangle data (points included), and the
    /// working memory kept from camera casts.
    [[nodiscard]] std::size_t memory_bytes() const {
        return points.size() * sizeof(double) + triangles.size() * sizeof(uint32_t) +
               (prim_ids.size() + point_ids.size()) * sizeof(uint32_t) +
               camera.nodes.size() * sizeof(CameraTree::Link) + wide.size() * sizeof(WideNode) +
               leaf_bytes.size() +
               (camera.leaf_offsets.size() + camera.leaf_points.size() + camera.point_end.size()) * sizeof(uint32_t) +
               camera.subtrees.size() * sizeof(CameraTree::Subtree) +
               (camera.top.size() + camera.shared.size()) * sizeof(uint32_t) + scratch->bytes();
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
/// then read neighbouring points. Unused points are dropped; point_ids keeps the input's.
void order_points(Scene& scene, const double* points, std::size_t n_points);

/// Sets the scene's camera tree from its BVH, once the points are in order.
void build_camera_tree(Scene& scene);

/// The same scene without a hierarchy (triangles in input order): all a single camera cast
/// needs, as its triangles are binned to the image's tiles instead (bin_triangles.hpp).
[[nodiscard]] Scene flat_scene(const double* points, std::size_t n_points, const uint32_t* triangles,
                               std::size_t n_triangles);

}  // namespace vrc
