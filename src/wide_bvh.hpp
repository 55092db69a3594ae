// The BVH as single rays go through it: eight children per node, their boxes side by side
// so one ray tests all eight in the lanes of one AVX register (two SSE registers in the
// baseline build; traverse_wide.hpp).
#pragma once

#include <cstdint>
#include <vector>

namespace vrc {

/// One node, 256 bytes (four cache lines). Lane c is a child: a node (`count[c] == 0`, at
/// `child[c]`), a leaf of triangles `child[c] .. child[c] + count[c] - 1`, or nothing
/// (an empty box: lo = +inf, hi = -inf, which no ray enters). Boxes are the binary BVH's,
/// single precision relative to the scene's anchor, rounded outward.
struct alignas(64) WideNode {
    static constexpr int kWidth = 8;
    float bounds[6][kWidth];  ///< lo x, y, z then hi x, y, z of each lane
    uint32_t child[kWidth];
    uint32_t count[kWidth];
};
static_assert(sizeof(WideNode) == 256, "wide nodes are meant to be four cache lines");

struct Scene;

/// Collapses the scene's binary BVH into eight-wide nodes (wide[0] the root), each node
/// taking in the largest-area grandchildren until it holds eight children (the collapse of
/// Wald, Benthin and Boulos, "Getting rid of packets", 2008). Leaves stay the binary
/// BVH's. Empty when the scene has no BVH nodes.
[[nodiscard]] std::vector<WideNode> collapse_to_wide(const Scene& scene);

}  // namespace vrc
