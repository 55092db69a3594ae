// The BVH as single rays go through it: four children per node, their boxes side by side
// so one ray tests all four in the lanes of one SIMD register (traverse_wide.hpp).
#pragma once

#include <cstdint>
#include <vector>

namespace vrc {

/// One node, 128 bytes (two cache lines). Lane c is a child: a node (`count[c] == 0`, at
/// `child[c]`), a leaf of triangles `child[c] .. child[c] + count[c] - 1`, or nothing
/// (an empty box: lo = +inf, hi = -inf, which no ray enters). Boxes are the binary BVH's,
/// single precision relative to the scene's anchor, rounded outward.
struct alignas(64) WideNode {
    static constexpr int kWidth = 4;
    float bounds[6][kWidth];  ///< lo x, y, z then hi x, y, z of each lane
    uint32_t child[kWidth];
    uint32_t count[kWidth];
};
static_assert(sizeof(WideNode) == 128, "wide nodes are meant to be two cache lines");

struct Scene;

/// Collapses the scene's binary BVH into four-wide nodes (wide[0] the root), each node
/// taking in the largest-area grandchildren until it holds four children (the collapse of
/// Wald, Benthin and Boulos, "Getting rid of packets", 2008). Leaves stay the binary
/// BVH's. Empty when the scene has no BVH nodes.
[[nodiscard]] std::vector<WideNode> collapse_to_wide(const Scene& scene);

}  // namespace vrc
