// Collapse of the binary BVH into eight-wide nodes (wide_bvh.hpp).
#include "wide_bvh.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <thread>

#include "bvh.hpp"
#include "geometry.hpp"

namespace vrc {
namespace {

/// A leaf whose block is placed but not yet filled: its word offset and triangles.
struct PendingLeaf {
    uint32_t at, first, count;
};

/// Places a block for leaf `node` after the others (filled later, fill_leaf) and returns
/// its word offset.
uint32_t add_leaf(const Node& node, std::vector<PendingLeaf>& pending, std::size_t& end) {
    const std::size_t at = end;
    end += LeafBlock::bytes(node.count);
    pending.push_back({uint32_t(at / 4), node.index, node.count});
    return uint32_t(at / 4);
}

/// Fills a placed leaf's block.
void fill_leaf(Scene& scene, const PendingLeaf& leaf) {
    const uint32_t n = leaf.count;
    LeafBlock& block = *new (scene.leaf_bytes.data() + 4 * std::size_t(leaf.at)) LeafBlock{};
    uint8_t* q = reinterpret_cast<uint8_t*>(&block + 1);
    block.first = leaf.first;
    double scaled[3][3][WideNode::kWidth];  // (exact up to a rounding of 2^-53)
    for (uint32_t c = 0; c < n; ++c)
        for (int v = 0; v < 3; ++v) {
            const double* p = scene.point(scene.triangles[3 * std::size_t(leaf.first + c) + v]);
            for (int k = 0; k < 3; ++k) scaled[v][k][c] = (p[k] - scene.anchor[k]) * scene.leaf_scale;
        }
    double error = 0;
    for (int k = 0; k < 3; ++k) {
        double lo = HUGE_VAL, hi = -HUGE_VAL;
        for (int v = 0; v < 3; ++v)
            for (uint32_t c = 0; c < n; ++c) lo = std::min(lo, scaled[v][k][c]), hi = std::max(hi, scaled[v][k][c]);
        block.lo[k] = round_down(lo);
        block.step[k] = round_up((hi - double(block.lo[k])) * (1.0 / 255));
        // (any level will do: the error is measured, not assumed)
        const double to_level = block.step[k] > 0 ? 1 / double(block.step[k]) : 0;
        for (int v = 0; v < 3; ++v)
            for (uint32_t c = 0; c < n; ++c) {
                const double x = scaled[v][k][c];
                const double level = std::min(std::max((x - block.lo[k]) * to_level + 0.5, 0.0), 255.0);
                const uint8_t byte = uint8_t(level);
                q[(3 * v + k) * n + c] = byte;
                // (this difference's own rounding in double is far below the filter's bounds)
                error = std::max(error, std::fabs(x - (double(block.lo[k]) + double(byte) * double(block.step[k]))));
            }
    }
    block.error = round_up(error * (1 + 0x1p-20));
}

/// Places binary node `from`'s subtree as wide node `at` (already allocated).
void place(Scene& scene, uint32_t from, uint32_t at, std::vector<PendingLeaf>& pending, std::size_t& end) {
    const std::vector<Node>& nodes = scene.nodes;
    std::vector<WideNode>& wide = scene.wide;
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
            node.bounds[k][c] = clear_of_tiny_lo(m.box.lo[k]);
            node.bounds[3 + k][c] = clear_of_tiny_hi(m.box.hi[k]);
        }
        if (m.is_leaf()) {
            node.child[c] = add_leaf(m, pending, end);
            node.count[c] = leaf_count(m.count, m.index);
        } else {
            node.child[c] = uint32_t(wide.size());
            wide.emplace_back();
            inner[n_inner++] = c;
        }
    }
    wide[at] = node;
    for (int i = 0; i < n_inner; ++i) {  // (depth <= the binary tree's, < 96: see bvh_build.cpp)
        const int c = inner[i];
        place(scene, members[c], wide[at].child[c], pending, end);
    }
}

}  // namespace

void build_wide(Scene& scene, unsigned threads) {
    std::vector<WideNode>& wide = scene.wide;
    wide.clear();
    scene.leaf_bytes.clear();
    if (scene.nodes.empty()) return;
    // The leaves' scale: the largest coordinate relative to the anchor in [0.5, 1)
    // (triangle_filter.hpp's error bounds take the coordinates within [-1, 1]).
    double reach = 0;
    for (std::size_t i = 0; i < scene.points.size(); i += 3)
        for (int k = 0; k < 3; ++k) reach = std::max(reach, std::fabs(scene.points[i + k] - scene.anchor[k]));
    // (beyond 2^+-1000 the scale and the filter's bounds would leave double's range: the
    // filter then lets every triangle through, leaf_scale 0)
    const int e = reach > 0 ? std::ilogb(reach) + 1 : 0;
    scene.leaf_scale = std::abs(e) <= 1000 ? std::ldexp(1.0, -e) : 0.0;
    wide.reserve(scene.nodes.size() / 2 + 1);
    wide.emplace_back();
    // The leaves' blocks laid out first (their bytes counted, so the array is made once),
    // then filled.
    std::size_t bytes = 8;  // (the last row's eight-byte reads)
    for (const Node& node : scene.nodes) {
        if (node.count > WideNode::kWidth) throw std::logic_error("a BVH leaf holds more than eight triangles");
        if (node.is_leaf()) bytes += LeafBlock::bytes(node.count);
    }
    if (bytes / 4 > UINT32_MAX) throw std::length_error("too many triangles for the single-ray leaves");
    reserve_huge(scene.leaf_bytes, bytes);
    scene.leaf_bytes.resize(bytes);
    std::vector<PendingLeaf> pending;
    pending.reserve(scene.nodes.size() / 2 + 1);
    std::size_t end = 0;
    const Node& root = scene.nodes[0];
    if (!root.is_leaf()) {
        place(scene, 0, 0, pending, end);
    } else {  // a scene of one leaf: a root with that leaf in its first lane
        WideNode& node = wide[0];
        for (int c = 0; c < WideNode::kWidth; ++c) {
            for (int k = 0; k < 3; ++k) {
                node.bounds[k][c] = c == 0 ? clear_of_tiny_lo(root.box.lo[k]) : std::numeric_limits<float>::infinity();
                node.bounds[3 + k][c] = c == 0 ? clear_of_tiny_hi(root.box.hi[k]) : -std::numeric_limits<float>::infinity();
            }
            node.child[c] = c == 0 ? add_leaf(root, pending, end) : 0;
            node.count[c] = c == 0 ? leaf_count(root.count, root.index) : 0;
        }
    }
    shrink_huge(wide);
    // The blocks filled on all threads: their points, read through the triangles, made
    // filling them a third of the frog's build on one.
    const unsigned workers = std::max(1u, std::min<unsigned>(threads, unsigned(pending.size() / 4096)));
    const auto fill = [&](unsigned w) {
        for (std::size_t i = pending.size() * w / workers, e = pending.size() * (w + 1) / workers; i < e; ++i)
            fill_leaf(scene, pending[i]);
    };
    std::vector<std::thread> helpers;
    for (unsigned w = 1; w < workers; ++w) helpers.emplace_back(fill, w);
    fill(0);
    for (std::thread& t : helpers) t.join();
    scene.indices_prefetched = scene.ray_bytes() >= kPrefetchedIndexBytes;
}

}  // namespace vrc
