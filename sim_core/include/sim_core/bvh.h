// Bounding volume hierarchy over triangles: binned SAH build, compact 32-byte nodes, sibling pairs stored
// next to each other so one 64-byte line fetch brings both children of a node (what the T&I unit's node
// cache sees). Triangles are stored in traversal (leaf) order as 48-byte records.
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
};

struct Bvh {
  std::vector<BvhNode> nodes;  // nodes[0] is the root, nodes[1] is padding, pairs start at 2
  int depth = 0;
  int leaf_count = 0;
};

// Builds the BVH and reorders `tris` into leaf order. `order_out` receives, for every record position,
// the index the record had in the input (so per-triangle side data can be permuted the same way).
Bvh build_bvh(std::vector<TriRecord>& tris, std::vector<std::uint32_t>* order_out,
              const BvhBuildOptions& options = {});

}  // namespace sim_core
