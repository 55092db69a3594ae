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
/// (`source`: the BVH node each camera node was made from)
void place(const std::vector<Node>& nodes, const std::vector<Run>& run, uint32_t from, uint32_t to,
           std::vector<CameraTree::Link>& out, std::vector<uint32_t>& source) {
    source[to] = from;
    if (run[from].count <= CameraTree::kMaxLeaf) {
        out[to] = {run[from].first, run[from].count};
        return;
    }
    const auto pair = uint32_t(out.size());
    out[to] = {pair, 0};
    out.resize(out.size() + 2);
    source.resize(out.size());
    place(nodes, run, nodes[from].index, pair, out, source);  // (depth < 96: see bvh_build.cpp)
    place(nodes, run, nodes[from].index + 1, pair + 1, out, source);
}

/// Splits the hierarchy into subtrees (CameraTree::subtrees, without their shared points):
/// the largest is split until there are enough to share among workers, or it is a leaf.
/// Relies on the builder's layout (sibling pairs, depth first): an inner node's
/// descendants are one block, from its children to the last pair of its rightmost inner
/// descendant.
void plan_subtrees(CameraTree& tree, const std::vector<Node>& bvh, const std::vector<uint32_t>& source) {
    using Subtree = CameraTree::Subtree;
    const std::vector<CameraTree::Link>& nodes = tree.nodes;
    const auto is_leaf = [&](uint32_t i) { return nodes[i].count != 0; };
    const auto subtree = [&](uint32_t root) {
        Subtree t{root, root, root, 0, 0, bvh[source[root]].box};
        if (is_leaf(root)) return t;
        // the block ends with the children of the last inner node on the way down that
        // takes the right child when it is inner, else the left one
        uint32_t i = root, last;
        do {
            last = nodes[i].index;
            i = is_leaf(last + 1) ? last : last + 1;
        } while (!is_leaf(i));
        t.first = nodes[root].index, t.end = last + 2;
        return t;
    };
    const auto size = [](const Subtree& t) { return t.end - t.first; };
    const auto smaller = [&](const Subtree& a, const Subtree& b) { return size(a) < size(b); };
    std::vector<Subtree>& subtrees = tree.subtrees;
    subtrees = {subtree(0)};
    while (subtrees.size() < CameraTree::kSubtrees && size(subtrees.front()) > 0) {
        std::pop_heap(subtrees.begin(), subtrees.end(), smaller);
        const uint32_t root = subtrees.back().root, left = nodes[root].index;
        tree.top.push_back(root);
        subtrees.back() = subtree(left);
        std::push_heap(subtrees.begin(), subtrees.end(), smaller);
        subtrees.push_back(subtree(left + 1));
        std::push_heap(subtrees.begin(), subtrees.end(), smaller);
    }
    // in the triangles' order (a subtree's first is its leftmost leaf's)
    const auto first_triangle = [&](const Subtree& t) {
        uint32_t i = t.root;
        while (!is_leaf(i)) i = nodes[i].index;
        return nodes[i].index;
    };
    std::sort(subtrees.begin(), subtrees.end(), [&](const Subtree& a, const Subtree& b) { return first_triangle(a) < first_triangle(b); });
}

/// Each subtree's points that the leaves of later subtrees also use (CameraTree::shared).
void share_points(CameraTree& tree, std::size_t n_points) {
    std::vector<uint32_t> owner(n_points);  // the subtree whose range holds each point
    for (uint32_t k = 0, begin = 0; k < tree.subtrees.size(); ++k) {
        const uint32_t end = tree.point_end[tree.subtrees[k].root];
        std::fill(owner.begin() + begin, owner.begin() + end, k);
        begin = end;
    }
    std::vector<bool> shared(n_points, false);
    for (uint32_t k = 0; k < tree.subtrees.size(); ++k) {
        const auto mark = [&](uint32_t node) {  // (an inner node lists no points)
            for (uint32_t j = tree.leaf_offsets[node]; j < tree.leaf_offsets[node + 1]; ++j)
                if (owner[tree.leaf_points[j]] != k) shared[tree.leaf_points[j]] = true;
        };
        mark(tree.subtrees[k].root);
        for (uint32_t i = tree.subtrees[k].first; i < tree.subtrees[k].end; ++i) mark(i);
    }
    for (uint32_t k = 0, begin = 0; k < tree.subtrees.size(); ++k) {
        const uint32_t end = tree.point_end[tree.subtrees[k].root];
        tree.subtrees[k].shared_begin = uint32_t(tree.shared.size());
        for (uint32_t p = begin; p < end; ++p)
            if (shared[p]) tree.shared.push_back(p);
        tree.subtrees[k].shared_end = uint32_t(tree.shared.size());
        begin = end;
    }
}

}  // namespace

void build_camera_tree(Scene& scene) {
    CameraTree& tree = scene.camera;
    tree = CameraTree{};
    if (scene.nodes.empty()) return;
    tree.nodes.resize(1);
    std::vector<uint32_t> source(1);
    place(scene.nodes, runs(scene.nodes), 0, 0, tree.nodes, source);
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
    plan_subtrees(tree, scene.nodes, source);
    share_points(tree, scene.points.size() / 3);
}

}  // namespace vrc
