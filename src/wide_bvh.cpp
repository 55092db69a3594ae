// Collapse of the binary BVH into eight-wide nodes (wide_bvh.hpp).
#include "wide_bvh.hpp"

#include <algorithm>
#include <limits>

#include "bvh.hpp"

namespace vrc {
namespace {

/// Places binary node `from`'s subtree as wide node `at` (already allocated).
void place(const std::vector<Node>& nodes, uint32_t from, uint32_t at, std::vector<WideNode>& wide) {
    uint32_t members[WideNode::kWidth] = {nodes[from].index, nodes[from].index + 1};
    int n = 2;
    while (n < WideNode::kWidth) {  // open the inner member of largest area
        int best = -1;
        float best_area = -1;
        for (int c = 0; c < n; ++c) {
            const Node& m = nodes[members[c]];
            if (!m.is_leaf() && m.box.half_area() > best_area) {
                best = c;
                best_area = m.box.half_area();
            }
        }
        if (best < 0) break;
        const uint32_t first = nodes[members[best]].index;
        members[best] = first;
        members[n++] = first + 1;
    }
    WideNode node;
    for (int c = 0; c < WideNode::kWidth; ++c) {
        for (int k = 0; k < 3; ++k) {
            node.bounds[k][c] = std::numeric_limits<float>::infinity();
            node.bounds[3 + k][c] = -std::numeric_limits<float>::infinity();
        }
        node.child[c] = node.count[c] = 0;
    }
    uint32_t inner[WideNode::kWidth];
    int n_inner = 0;
    for (int c = 0; c < n; ++c) {
        const Node& m = nodes[members[c]];
        for (int k = 0; k < 3; ++k) {
            node.bounds[k][c] = m.box.lo[k];
            node.bounds[3 + k][c] = m.box.hi[k];
        }
        if (m.is_leaf()) {
            node.child[c] = m.index;
            node.count[c] = m.count;
        } else {
            node.child[c] = uint32_t(wide.size());
            wide.emplace_back();
            inner[n_inner++] = c;
        }
    }
    wide[at] = node;
    for (int i = 0; i < n_inner; ++i) {  // (depth <= the binary tree's, < 96: see bvh_build.cpp)
        const int c = inner[i];
        place(nodes, members[c], wide[at].child[c], wide);
    }
}

}  // namespace

std::vector<WideNode> collapse_to_wide(const Scene& scene) {
    std::vector<WideNode> wide;
    if (scene.nodes.empty()) return wide;
    wide.reserve(scene.nodes.size() / 2 + 1);
    wide.emplace_back();
    const Node& root = scene.nodes[0];
    if (!root.is_leaf()) {
        place(scene.nodes, 0, 0, wide);
    } else {  // a scene of one leaf: a root with that leaf in its first lane
        WideNode& node = wide[0];
        for (int c = 0; c < WideNode::kWidth; ++c) {
            for (int k = 0; k < 3; ++k) {
                node.bounds[k][c] = c == 0 ? root.box.lo[k] : std::numeric_limits<float>::infinity();
                node.bounds[3 + k][c] = c == 0 ? root.box.hi[k] : -std::numeric_limits<float>::infinity();
            }
            node.child[c] = c == 0 ? root.index : 0;
            node.count[c] = c == 0 ? root.count : 0;
        }
    }
    shrink_huge(wide);
    return wide;
}

}  // namespace vrc
