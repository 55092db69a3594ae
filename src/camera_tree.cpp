// The camera tree (bvh.hpp): the BVH with its small subtrees collapsed into leaves, and
// each leaf's points.
#include <algorithm>
#include <cstdint>
#include <vector>

#include "bvh.hpp"

namespace vrc {
namespace {

/// Each BVH node's triangles: its first and their count, or kMixed when they are not one
/// run (never so from bvh_build.cpp, which partitions a node's triangles in place; checked,
/// as a collapsed leaf must be a run).
struct Run {
    static constexpr uint32_t kMixed = UINT32_MAX;
    uint32_t first, count;
};

std::vector<Run> runs(const std::vector<Node>& nodes) {
    std::vector<Run> run(nodes.size());
    for (std::size_t i = nodes.size(); i-- > 0;) {  // children follow their parent
        const Node& n = nodes[i];
        if (n.is_leaf()) {
            run[i] = {n.index, n.count};
            continue;
        }
        const Run &a = run[n.index], &b = run[n.index + 1];
        const bool joined = a.count != Run::kMixed && b.count != Run::kMixed && a.first + a.count == b.first;
        run[i] = {a.first, joined ? a.count + b.count : Run::kMixed};
    }
    return run;
}

/// Writes BVH node `from` as camera node `to`, then its descendants: a pair of children
/// at a time, the left one's descendants before the right one's (the BVH's layout).
void place(const std::vector<Node>& nodes, const std::vector<Run>& run, uint32_t from, uint32_t to,
           std::vector<CameraTree::Link>& out) {
    if (run[from].count <= CameraTree::kMaxLeaf) {
        out[to] = {run[from].first, run[from].count};
        return;
    }
    const auto pair = uint32_t(out.size());
    out[to] = {pair, 0};
    out.resize(out.size() + 2);
    place(nodes, run, nodes[from].index, pair, out);  // (depth < 96: see bvh_build.cpp)
    place(nodes, run, nodes[from].index + 1, pair + 1, out);
}

}  // namespace

void build_camera_tree(Scene& scene) {
    CameraTree& tree = scene.camera;
    tree = CameraTree{};
    if (scene.nodes.empty()) return;
    tree.nodes.resize(1);
    place(scene.nodes, runs(scene.nodes), 0, 0, tree.nodes);
    shrink_huge(tree.nodes);

    std::vector<uint32_t>& list = tree.leaf_points;
    std::vector<uint32_t> listed_by(scene.points.size() / 3, UINT32_MAX);  // the last leaf to list each point
    reserve_huge(tree.leaf_offsets, tree.nodes.size() + 1);
    tree.leaf_offsets.resize(tree.nodes.size() + 1);
    reserve_huge(list, scene.points.size() / 3 * 2);
    for (uint32_t i = 0; i < tree.nodes.size(); ++i) {
        tree.leaf_offsets[i] = uint32_t(list.size());
        const CameraTree::Link& node = tree.nodes[i];
        for (const uint32_t *p = scene.triangles.data() + 3 * std::size_t(node.index), *end = p + 3 * node.count; p != end; ++p)
            if (listed_by[*p] != i) listed_by[*p] = i, list.push_back(*p);
    }
    tree.leaf_offsets.back() = uint32_t(list.size());
    shrink_huge(list);

    // point_end: over the triangles up to each leaf's last, then each inner node's from its
    // children (the right child's range ends later)
    const std::size_t n_triangles = scene.triangles.size() / 3;
    std::vector<uint32_t> prefix(n_triangles + 1, 0);
    for (std::size_t t = 0; t < n_triangles; ++t) {
        const uint32_t* tri = scene.triangles.data() + 3 * t;
        prefix[t + 1] = std::max({prefix[t], tri[0] + 1, tri[1] + 1, tri[2] + 1});
    }
    tree.point_end.resize(tree.nodes.size());
    for (std::size_t i = tree.nodes.size(); i-- > 0;) {  // children follow their parent
        const CameraTree::Link& node = tree.nodes[i];
        tree.point_end[i] = node.count != 0 ? prefix[node.index + node.count] : std::max(tree.point_end[node.index], tree.point_end[node.index + 1]);
    }
}

}  // namespace vrc
