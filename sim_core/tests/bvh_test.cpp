// BVH and BVH4 invariants: every triangle in exactly one leaf, child boxes inside their parents, BVH4
// blocks hold the records' vertices, empty slots are inverted boxes; the parallel build is identical for
// any thread count.
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "sim_core/bvh.h"
#include "sim_core/scene.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

void check_bvh(const Scene& s) {
  const Bvh& b = s.bvh();
  std::vector<int> seen(s.triangle_count(), 0);
  for (std::size_t i = 0; i < b.nodes.size(); ++i) {
    if (i == 1) continue;  // padding
    const BvhNode& n = b.nodes[i];
    if (n.count == 0) {
      CHECK(n.first % 2 == 0 && n.first + 1 < b.nodes.size());
      for (int c = 0; c < 2; ++c) {
        const BvhNode& ch = b.nodes[n.first + c];
        for (int a = 0; a < 3; ++a) CHECK(ch.lo[a] >= n.lo[a] && ch.hi[a] <= n.hi[a]);
      }
    } else {
      CHECK(n.count <= 4);
      for (std::uint32_t t = n.first; t < n.first + n.count; ++t) {
        ++seen[t];
        for (int k = 0; k < 9; ++k) CHECK(s.tri(t).v[k] >= n.lo[k % 3] && s.tri(t).v[k] <= n.hi[k % 3]);
      }
    }
  }
  for (int c : seen) CHECK(c == 1);
}

// Walks the 4-wide BVH: every triangle in exactly one leaf block, blocks hold the records' vertices,
// every child box holds its subtree's triangles, empty slots are inverted boxes.
void check_bvh4_node(const Scene& s, std::uint32_t idx, const float* box_lo, const float* box_hi,
                     std::vector<int>* seen, int level) {
  const Bvh4& b = s.bvh4();
  CHECK(idx < b.nodes.size() && level <= 64);
  if (idx >= b.nodes.size() || level > 64) return;
  const Bvh4Node& n = b.nodes[idx];
  for (int i = 0; i < 4; ++i) {
    const float lo[3] = {n.box[0][i], n.box[2][i], n.box[4][i]}, hi[3] = {n.box[1][i], n.box[3][i], n.box[5][i]};
    if (n.count[i] == 0 && lo[0] > hi[0]) {  // empty slot
      for (int a = 0; a < 3; ++a) CHECK(std::isinf(lo[a]) && lo[a] > 0 && std::isinf(hi[a]) && hi[a] < 0);
      continue;
    }
    if (box_lo)
      for (int a = 0; a < 3; ++a) CHECK(lo[a] >= box_lo[a] && hi[a] <= box_hi[a]);
    if (n.count[i] == 0) {
      check_bvh4_node(s, n.child[i], lo, hi, seen, level + 1);
      continue;
    }
    std::uint32_t left = n.count[i];
    for (std::uint32_t k = n.child[i]; left > 0; ++k) {
      CHECK(k < b.blocks.size());
      if (k >= b.blocks.size()) return;
      const TriBlock4& blk = b.blocks[k];
      CHECK(blk.count == std::min(4u, left));
      for (std::uint32_t l = 0; l < blk.count; ++l) {
        const TriRecord& t = s.tri(blk.first + l);
        ++(*seen)[blk.first + l];
        for (int v = 0; v < 3; ++v)
          for (int a = 0; a < 3; ++a) {
            CHECK(blk.v[v][a][l] == t.v[3 * v + a]);
            CHECK(t.v[3 * v + a] >= lo[a] && t.v[3 * v + a] <= hi[a]);
          }
      }
      left -= blk.count;
    }
  }
}

void check_bvh4(const Scene& s) {
  std::vector<int> seen(s.triangle_count(), 0);
  check_bvh4_node(s, 0, nullptr, nullptr, &seen, 0);
  for (int c : seen) CHECK(c == 1);
}

// The parallel build gives the same tree, bit for bit, for any thread count (40K triangles: enough for
// the builder to fork its top levels).
void check_parallel_build_identical() {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-10.f, 10.f), e(-0.3f, 0.3f);
  std::vector<TriRecord> base(40000);
  for (std::size_t i = 0; i < base.size(); ++i) {
    const float cx = u(rng), cy = u(rng), cz = u(rng) * (i % 3 == 0 ? 0.1f : 1.f);  // clustered slabs
    for (int k = 0; k < 3; ++k) {
      base[i].v[3 * k] = cx + e(rng);
      base[i].v[3 * k + 1] = cy + e(rng);
      base[i].v[3 * k + 2] = cz + e(rng);
    }
    base[i].prim = static_cast<std::uint32_t>(i);
    base[i].material = base[i].object = 0;
  }
  std::vector<BvhNode> ref_nodes;
  std::vector<std::uint32_t> ref_order;
  int ref_depth = 0, ref_leaves = 0;
  for (int threads : {1, 2, 3, 4, 8}) {
    std::vector<TriRecord> tris = base;
    std::vector<std::uint32_t> order;
    BvhBuildOptions opt;
    opt.threads = threads;
    const Bvh b = build_bvh(tris, &order, opt);
    if (threads == 1) {
      ref_nodes = b.nodes; ref_order = order; ref_depth = b.depth; ref_leaves = b.leaf_count;
      continue;
    }
    CHECK(b.nodes.size() == ref_nodes.size() && order == ref_order);
    CHECK(b.depth == ref_depth && b.leaf_count == ref_leaves);
    CHECK(b.nodes.size() == ref_nodes.size() &&
          std::memcmp(b.nodes.data(), ref_nodes.data(), b.nodes.size() * sizeof(BvhNode)) == 0);
  }
}

}  // namespace

int main() {
  const Scene s = test::make_scene();
  check_bvh(s);
  check_bvh4(s);
  check_parallel_build_identical();
  return check_exit_code();
}
