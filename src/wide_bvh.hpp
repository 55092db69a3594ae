// The BVH as single rays go through it: eight children per node, their boxes side by side
// so one ray tests all eight in the lanes of one AVX register (two SSE registers in the
// baseline build; traverse_wide.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace vrc {

/// One node, 256 bytes (four cache lines). Lane c is a child: a node (`count[c] == 0`, at
/// `child[c]`), a leaf (its LeafBlock at word `child[c]` of the scene's leaf_bytes; its
/// size and first triangle in `count[c]`, leaf_size and leaf_first_hint), or nothing
/// (an empty box: lo = +inf, hi = -inf, which no ray enters). Boxes are the binary BVH's,
/// single precision relative to the scene's anchor, rounded outward.
struct alignas(64) WideNode {
    static constexpr int kWidth = 8;
    float bounds[6][kWidth];  ///< lo x, y, z then hi x, y, z of each lane
    uint32_t child[kWidth];
    uint32_t count[kWidth];
};
static_assert(sizeof(WideNode) == 256, "wide nodes are meant to be four cache lines");

/// Magnitudes below this (but 0) appear in no wide node's bounds and no ray's numbers in
/// its float slab tests (FloatLanes in traverse_wide.hpp), so that none of their
/// differences and products is subnormal: Intel cores take about a hundred cycles, in
/// microcode, over each instruction that meets a subnormal number. (A ray from a box's
/// middle, a lidar's or a camera's, met them in every node whose bounds pass through it.)
constexpr float kTinyBound = 0x1p-64f;
/// A box's lower (upper) bound moved outward, to 0 or -kTinyBound (kTinyBound), when its
/// magnitude is below kTinyBound.
inline float clear_of_tiny_lo(float lo) {
    if (!(lo > -kTinyBound && lo < kTinyBound) || lo == 0) return lo;
    return lo > 0 ? 0.0f : -kTinyBound;
}
inline float clear_of_tiny_hi(float hi) {
    if (!(hi > -kTinyBound && hi < kTinyBound) || hi == 0) return hi;
    return hi < 0 ? 0.0f : kTinyBound;
}

/// A leaf lane's `count`: its triangles (1 to 8) in the low four bits, its first triangle
/// above them, so that a search can ask for the leaf's point indices together with its
/// block (the block holds the first triangle too, but reading it would wait for the block).
/// The first triangle's low 28 bits only: beyond, the hint is wrong and only a request is.
inline uint32_t leaf_count(uint32_t size, uint32_t first) { return size | first << 4; }
inline uint32_t leaf_size(uint32_t count) { return count & 15; }
inline uint32_t leaf_first_hint(uint32_t count) { return count >> 4; }

/// A leaf's triangles (at most eight) as the single-ray filter reads them
/// (triangle_filter.hpp): lane c is triangle first + c, each corner's coordinates relative
/// to the scene's anchor, scaled by leaf_scale (a power of two: they lie within [-1, 1]) and
/// quantized to 8 bits in the leaf's box: lo + q * step, within `error` of the exact scaled
/// coordinate. The quantized coordinates follow the header: nine rows (corner, axis) of
/// `count` bytes. A leaf's tests read its 32 + 9 count contiguous bytes rather than
/// gather up to 24 points through the triangles. Eight bits, not floats: a 20 k-triangle
/// scene's blocks then stay in the L2 cache, and the scene within the memory budget. The
/// price is the grid's error (a 255th of the leaf's size in the filter's bound): near-misses
/// close to a ray's origin, as around a ray leaving the surface, go on to the exact test.
struct LeafBlock {
    float lo[3], step[3];
    float error;
    uint32_t first;  ///< the leaf's first triangle (leaf order)
    /// Row r (corner r / 3, axis r % 3) of a leaf of `count` triangles. Eight bytes may be
    /// read from it: those past the row belong to the next one, or to the padding after
    /// the last block.
    [[nodiscard]] const uint8_t* row(int r, uint32_t count) const {
        return reinterpret_cast<const uint8_t*>(this + 1) + std::size_t(r) * count;
    }
    /// Bytes of a leaf of `count` triangles, in whole words (the next header's alignment).
    static constexpr std::size_t bytes(uint32_t count) { return sizeof(LeafBlock) + (9 * count + 3) / 4 * 4; }
};
static_assert(sizeof(LeafBlock) == 32, "a leaf's header is meant to be 32 bytes");

struct Scene;

/// Scenes whose single-ray data (Scene::ray_bytes) take this much memory or more (beyond an
/// L1 cache) have a leaf's point indices asked for before its filter runs, when rays go one
/// at a time (Scene::indices_prefetched).
constexpr std::size_t kPrefetchedIndexBytes = std::size_t(256) << 10;

/// Collapses the scene's binary BVH into eight-wide nodes (scene.wide, wide[0] the root),
/// each node taking in the largest-area grandchildren until it holds eight children (the
/// collapse of Wald, Benthin and Boulos, "Getting rid of packets", 2008), and sets the
/// leaves' blocks (scene.leaf_bytes, leaf_scale, indices_prefetched). Leaves stay the
/// binary BVH's. Empty when the scene has no BVH nodes. Its points must be in their final order. The
/// leaves' blocks are filled on up to `threads` threads.
void build_wide(Scene& scene, unsigned threads);

}  // namespace vrc
