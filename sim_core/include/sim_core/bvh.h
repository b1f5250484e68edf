// Bounding volume hierarchy over triangles: binned SAH build of a binary tree (compact 32-byte nodes, sibling
// pairs stored next to each other so one 64-byte line fetch brings both children of a node), collapsed into
// the 4-wide tree the renderer walks (Bvh4). Triangles are stored in traversal (leaf) order as 48-byte
// records, the unit the T&I model fetches and tests.
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/math.h"

namespace sim_core {

// One BVH node, exactly 32 bytes. count == 0: interior node whose children are nodes[first] and
// nodes[first + 1]; count > 0: leaf holding triangles [first, first + count).
struct BvhNode {
  float lo[3];
  std::uint32_t first;
  float hi[3];
  std::uint32_t count;
};
static_assert(sizeof(BvhNode) == 32, "BVH nodes must be 32 bytes");

// Triangle as the intersection unit fetches it (48 bytes): vertices, original index, material, object.
struct TriRecord {
  float v[9];               // v0.xyz, v1.xyz, v2.xyz
  std::uint32_t prim;       // index of the triangle in the caller's original array
  std::uint32_t material;
  std::uint32_t object;
};
static_assert(sizeof(TriRecord) == 48, "triangle records must be 48 bytes");

// Virtual addresses the cache model sees (node array and triangle array in separate DRAM regions).
inline constexpr std::uint64_t kNodeBaseAddress = 0x10000000ull;
inline constexpr std::uint64_t kTriBaseAddress = 0x80000000ull;

struct BvhBuildOptions {
  int bins = 16;          // SAH bins per axis
  int max_leaf_size = 4;  // leaves never hold more triangles than this
  float traversal_cost = 1.0f;
  float intersection_cost = 1.0f;
  int threads = 0;  // build threads (0 = hardware concurrency); the tree is identical for any count
};

struct Bvh {
  std::vector<BvhNode> nodes;  // nodes[0] is the root, nodes[1] is padding, pairs start at 2
  int depth = 0;
  int leaf_count = 0;
};

// 4-wide node, 128 bytes (two 64-byte lines): what the renderer (and with it the energy model's T&I unit)
// and the host-side queries walk. Child boxes in SoA order so one SSE slab test covers all four. Collapsed
// from the binary SAH tree, so its boxes are the binary tree's and its leaves the binary leaves, except that
// a subtree of at most four triangles becomes one leaf (one SIMD block); only the interior levels are merged.
// count[i] == 0: child i is interior node child[i] (or an empty slot, whose box is inverted so every ray
// misses it); count[i] > 0: child i is a leaf of count[i] triangles stored from block child[i] on.
// One visit of a node tests its four child boxes (empty slots included) in one step; the cache model sees
// it as a 128-byte fetch at kNodeBaseAddress + index * 128.
struct alignas(64) Bvh4Node {
  float box[6][4];  // lo.x, hi.x, lo.y, hi.y, lo.z, hi.z, each for children 0..3
  std::uint32_t child[4];
  std::uint32_t count[4];
};
static_assert(sizeof(Bvh4Node) == 128, "BVH4 nodes must be 128 bytes");
// Ray-box tests of one visit (step) of a 4-wide node: its four child slots, empty ones included, as the
// modelled T&I unit tests them.
inline constexpr std::uint32_t kBoxesPerNodeStep = 4;

// Up to four triangles of one leaf in SoA order (v[vertex][axis][lane]) for a 4-wide triangle test.
struct alignas(16) TriBlock4 {
  float v[3][3][4];
  std::uint32_t first;  // index of lane 0's triangle in the scene's (leaf-ordered) records
  std::uint32_t count;  // valid lanes, 1..4
  std::uint32_t pad[2];
};
static_assert(sizeof(TriBlock4) == 160, "triangle blocks must be 160 bytes");

struct Bvh4 {
  std::vector<Bvh4Node> nodes;  // nodes[0] is the root
  std::vector<TriBlock4> blocks;  // a leaf child's child[i] is its first block, ceil(count / 4) blocks
  int depth = 0;
};

// Collapses a binary BVH into a BVH4: each 4-wide node takes the binary children of a node and repeatedly
// opens the interior child of largest surface area until it holds four (or only leaves remain).
// Deterministic; a binary root that is a leaf becomes a root with one child.
// `tris` are the leaf-ordered records the binary BVH indexes (for the SoA triangle blocks).
Bvh4 collapse_bvh4(const Bvh& bvh, const std::vector<TriRecord>& tris);

// Builds the BVH and reorders `tris` into leaf order. `order_out` receives, for every record position,
// the index the record had in the input (so per-triangle side data can be permuted the same way).
Bvh build_bvh(std::vector<TriRecord>& tris, std::vector<std::uint32_t>* order_out,
              const BvhBuildOptions& options = {});

}  // namespace sim_core
