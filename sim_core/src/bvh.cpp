#include "sim_core/bvh.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <future>
#include <limits>
#include <thread>
#include <stdexcept>

namespace sim_core {
namespace {

constexpr int kMaxBins = 32;

struct Aabb {
  Vec3 lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
          std::numeric_limits<float>::infinity()};
  Vec3 hi{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
          -std::numeric_limits<float>::infinity()};
  void grow(Vec3 p) { lo = vmin(lo, p); hi = vmax(hi, p); }
  void grow(const Aabb& b) { lo = vmin(lo, b.lo); hi = vmax(hi, b.hi); }
  bool empty() const { return lo.x > hi.x; }
  float area() const {
    if (empty()) return 0.f;
    const Vec3 e = hi - lo;
    return 2.f * (e.x * e.y + e.y * e.z + e.z * e.x);
  }
};

struct PrimInfo {
  Aabb box;
  Vec3 centroid;
};

// Builds one subtree into its own node array. Subtrees over disjoint index ranges can be built by
// different threads: prims is read-only and each builder partitions only its own range of `index`.
struct Builder {
  const BvhBuildOptions& opt;
  const std::vector<PrimInfo>& prims;
  std::vector<std::uint32_t>& index;  // permutation being partitioned
  std::vector<BvhNode> nodes;
  int max_depth = 0;
  int leaves = 0;

  Builder(const BvhBuildOptions& o, const std::vector<PrimInfo>& p, std::vector<std::uint32_t>& i)
      : opt(o), prims(p), index(i) {}

  void make_leaf(std::uint32_t node, std::uint32_t begin, std::uint32_t end) {
    nodes[node].first = begin;
    nodes[node].count = end - begin;
    ++leaves;
  }

  void set_box(std::uint32_t node, std::uint32_t begin, std::uint32_t end) {
    const BvhNode b = box_of(begin, end);
    for (int a = 0; a < 3; ++a) { nodes[node].lo[a] = b.lo[a]; nodes[node].hi[a] = b.hi[a]; }
  }

  BvhNode box_of(std::uint32_t begin, std::uint32_t end) const {
    Aabb b;
    for (std::uint32_t i = begin; i < end; ++i) b.grow(prims[index[i]].box);
    // One ulp of outward padding: a ray lying exactly in a box face (axis-parallel, zero direction
    // component) then sees the slab as open instead of as an empty interval 0 * (1 / tiny) = 0.
    BvhNode n{};
    for (int a = 0; a < 3; ++a) {
      n.lo[a] = std::nextafter(b.lo[a], -std::numeric_limits<float>::infinity());
      n.hi[a] = std::nextafter(b.hi[a], std::numeric_limits<float>::infinity());
    }
    return n;
  }

  // Recursive build of node `node` over index[begin, end); the node's box is already set.
  void build(std::uint32_t node, std::uint32_t begin, std::uint32_t end, int depth) {
    max_depth = std::max(max_depth, depth);
    std::uint32_t mid = 0;
    if (!split(nodes[node], begin, end, depth, &mid)) { make_leaf(node, begin, end); return; }
    const std::uint32_t left = static_cast<std::uint32_t>(nodes.size());
    nodes.push_back(BvhNode{});
    nodes.push_back(BvhNode{});
    nodes[node].first = left;
    nodes[node].count = 0;
    set_box(left, begin, mid);
    set_box(left + 1, mid, end);
    build(left, begin, mid, depth + 1);
    build(left + 1, mid, end, depth + 1);
  }

  // Binned SAH decision for a node with box `box` over index[begin, end): false = make a leaf; true =
  // index[begin, end) is partitioned at *mid into the two children's ranges.
  bool split(const BvhNode& box, std::uint32_t begin, std::uint32_t end, int depth, std::uint32_t* mid_out) {
    const std::uint32_t n = end - begin;
    if (n <= 1 || depth >= 60) return false;
    Aabb cb;
    for (std::uint32_t i = begin; i < end; ++i) cb.grow(prims[index[i]].centroid);
    const Vec3 extent = cb.hi - cb.lo;
    Aabb nb;
    for (int a = 0; a < 3; ++a) { nb.lo[a] = box.lo[a]; nb.hi[a] = box.hi[a]; }
    const float parent_area = nb.area();

    int best_axis = -1, best_split = -1;
    float best_cost = std::numeric_limits<float>::infinity();
    const int bins = std::min(std::max(opt.bins, 2), kMaxBins);
    std::array<Aabb, kMaxBins> bin_box;
    std::array<std::uint32_t, kMaxBins> bin_count;
    std::array<float, kMaxBins> right_area{};
    std::array<std::uint32_t, kMaxBins> right_count{};
    for (int axis = 0; axis < 3; ++axis) {
      if (!(extent[axis] > 0.f)) continue;
      const float scale = static_cast<float>(bins) / extent[axis];
      std::fill(bin_box.begin(), bin_box.begin() + bins, Aabb{});
      std::fill(bin_count.begin(), bin_count.begin() + bins, 0u);
      for (std::uint32_t i = begin; i < end; ++i) {
        const PrimInfo& p = prims[index[i]];
        int b = static_cast<int>((p.centroid[axis] - cb.lo[axis]) * scale);
        b = std::min(std::max(b, 0), bins - 1);
        bin_box[b].grow(p.box);
        ++bin_count[b];
      }
      Aabb acc;
      std::uint32_t cnt = 0;
      for (int b = bins - 1; b > 0; --b) {
        acc.grow(bin_box[b]); cnt += bin_count[b];
        right_area[b] = acc.area(); right_count[b] = cnt;
      }
      acc = Aabb{}; cnt = 0;
      for (int b = 0; b < bins - 1; ++b) {
        acc.grow(bin_box[b]); cnt += bin_count[b];
        if (cnt == 0 || right_count[b + 1] == 0) continue;
        const float cost = acc.area() * static_cast<float>(cnt) +
                           right_area[b + 1] * static_cast<float>(right_count[b + 1]);
        if (cost < best_cost) { best_cost = cost; best_axis = axis; best_split = b; }
      }
    }
    const float leaf_cost = opt.intersection_cost * static_cast<float>(n);
    const float split_cost = parent_area > 0.f
        ? opt.traversal_cost + opt.intersection_cost * best_cost / parent_area
        : std::numeric_limits<float>::infinity();
    if (n <= static_cast<std::uint32_t>(opt.max_leaf_size) && leaf_cost <= split_cost) {
      return false;
    }
    std::uint32_t mid;
    if (best_axis < 0) {
      // Every centroid coincides: split by count so leaves stay small.
      mid = begin + n / 2;
    } else {
      const float scale = static_cast<float>(bins) / extent[best_axis];
      auto it = std::partition(index.begin() + begin, index.begin() + end, [&](std::uint32_t id) {
        int b = static_cast<int>((prims[id].centroid[best_axis] - cb.lo[best_axis]) * scale);
        b = std::min(std::max(b, 0), bins - 1);
        return b <= best_split;
      });
      mid = static_cast<std::uint32_t>(it - index.begin());
      if (mid == begin || mid == end) mid = begin + n / 2;
    }
    *mid_out = mid;
    return true;
  }
};

// A built subtree: `self` is its root node; `sub` holds the nodes below it in the order the serial
// depth-first build allocates them ([children pair] + sub(left) + sub(right)); interior `first` indices
// are relative to sub[0]. Concatenating chunks this way reproduces the serial layout exactly, so the tree
// is the same for any thread count.
struct Chunk {
  BvhNode self{};
  std::vector<BvhNode> sub;
  int max_depth = 0;
  int leaves = 0;
};

void append_relocated(std::vector<BvhNode>* out, const std::vector<BvhNode>& src, std::uint32_t offset) {
  for (BvhNode n : src) {
    if (n.count == 0) n.first += offset;
    out->push_back(n);
  }
}

constexpr std::uint32_t kMinParallelPrims = 8192;  // smaller subtrees are not worth a thread

Chunk build_chunk(const BvhBuildOptions& opt, const std::vector<PrimInfo>& prims, std::vector<std::uint32_t>& index,
                  const BvhNode& box, std::uint32_t begin, std::uint32_t end, int depth, int fork_levels) {
  Builder b(opt, prims, index);
  Chunk c;
  std::uint32_t mid = 0;
  if (fork_levels <= 0 || end - begin < kMinParallelPrims) {
    b.nodes.reserve(2 * static_cast<std::size_t>(end - begin) + 2);
    b.nodes.push_back(box);
    b.nodes.push_back(BvhNode{});  // padding: keeps sibling pairs at even indices, as in the global array
    b.build(0, begin, end, depth);
    c.self = b.nodes[0];
    if (c.self.count == 0) c.self.first -= 2;
    c.sub.assign(b.nodes.begin() + 2, b.nodes.end());
    for (BvhNode& n : c.sub)
      if (n.count == 0) n.first -= 2;
    c.max_depth = b.max_depth;
    c.leaves = b.leaves;
    return c;
  }
  c.self = box;
  c.max_depth = depth;
  if (!b.split(box, begin, end, depth, &mid)) {
    c.self.first = begin;
    c.self.count = end - begin;
    c.leaves = 1;
    return c;
  }
  const BvhNode lbox = b.box_of(begin, mid), rbox = b.box_of(mid, end);
  auto left_job = std::async(std::launch::async, [&] {
    return build_chunk(opt, prims, index, lbox, begin, mid, depth + 1, fork_levels - 1);
  });
  Chunk right = build_chunk(opt, prims, index, rbox, mid, end, depth + 1, fork_levels - 1);
  Chunk left = left_job.get();
  c.self.first = 0;
  c.self.count = 0;
  c.sub.reserve(2 + left.sub.size() + right.sub.size());
  const std::uint32_t loff = 2, roff = 2 + static_cast<std::uint32_t>(left.sub.size());
  append_relocated(&c.sub, {left.self}, loff);
  append_relocated(&c.sub, {right.self}, roff);
  append_relocated(&c.sub, left.sub, loff);
  append_relocated(&c.sub, right.sub, roff);
  c.max_depth = std::max(left.max_depth, right.max_depth);
  c.leaves = left.leaves + right.leaves;
  return c;
}

}  // namespace

Bvh build_bvh(std::vector<TriRecord>& tris, std::vector<std::uint32_t>* order_out,
              const BvhBuildOptions& options) {
  if (tris.empty()) throw std::invalid_argument("cannot build a BVH over zero triangles");
  if (tris.size() >= (1ull << 31)) throw std::invalid_argument("too many triangles");
  const std::uint32_t n = static_cast<std::uint32_t>(tris.size());
  std::vector<PrimInfo> prims(n);
  std::vector<std::uint32_t> index(n);
  for (std::uint32_t i = 0; i < n; ++i) {
    const float* v = tris[i].v;
    PrimInfo& p = prims[i];
    for (int k = 0; k < 3; ++k) p.box.grow(Vec3(v[3 * k], v[3 * k + 1], v[3 * k + 2]));
    p.centroid = (p.box.lo + p.box.hi) * 0.5f;
    index[i] = i;
  }
  int threads = options.threads > 0 ? options.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(1, std::min(threads, 256));
  int fork_levels = 0;  // 2^fork_levels subtrees for `threads` workers, x2 for load balance
  while ((1 << fork_levels) < threads) ++fork_levels;
  if (threads > 1) ++fork_levels;
  const BvhNode root_box = Builder(options, prims, index).box_of(0, n);
  Chunk root = build_chunk(options, prims, index, root_box, 0, n, 0, fork_levels);
  Bvh out;
  out.nodes.reserve(2 + root.sub.size());
  append_relocated(&out.nodes, {root.self}, 2);
  out.nodes.push_back(BvhNode{});  // padding: sibling pairs start at an even index (one 64-byte line)
  append_relocated(&out.nodes, root.sub, 2);
  out.depth = root.max_depth;
  out.leaf_count = root.leaves;

  std::vector<TriRecord> sorted(n);
  for (std::uint32_t i = 0; i < n; ++i) sorted[i] = tris[index[i]];
  tris.swap(sorted);
  if (order_out) *order_out = std::move(index);
  return out;
}

namespace {

float node_area(const BvhNode& n) {
  const float ex = n.hi[0] - n.lo[0], ey = n.hi[1] - n.lo[1], ez = n.hi[2] - n.lo[2];
  return 2.f * (ex * ey + ey * ez + ez * ex);
}

struct Collapser {
  const std::vector<BvhNode>& bin;
  const std::vector<TriRecord>& tris;
  std::vector<Bvh4Node>& out;
  std::vector<TriBlock4>& blocks;
  int depth = 0;
  std::vector<std::uint32_t> lo, hi;  // triangle range [lo, hi) of every binary node's subtree

  void ranges(std::uint32_t b) {
    if (bin[b].count > 0) { lo[b] = bin[b].first; hi[b] = bin[b].first + bin[b].count; return; }
    const std::uint32_t c = bin[b].first;
    ranges(c);
    ranges(c + 1);
    lo[b] = std::min(lo[c], lo[c + 1]);
    hi[b] = std::max(hi[c], hi[c + 1]);
  }
  // A subtree of at most four triangles is one SIMD block: testing it costs about one node test. (Merging
  // up to 8 was 5-10 % faster for scene.intersect on the bunny but tested 8x the binary walk's triangles
  // per shadow ray on the teapot scene, where the renderer got slower; at 4, the renderer's triangle
  // tests per ray stay within 1.3-1.7x of the binary walk's.)
  bool as_leaf(std::uint32_t b) const { return bin[b].count > 0 || hi[b] - lo[b] <= 4; }

  std::uint32_t add_blocks(std::uint32_t first, std::uint32_t count) {
    const std::uint32_t start = static_cast<std::uint32_t>(blocks.size());
    for (std::uint32_t b = 0; b < count; b += 4) {
      TriBlock4 blk{};
      blk.first = first + b;
      blk.count = std::min<std::uint32_t>(4, count - b);
      for (std::uint32_t l = 0; l < blk.count; ++l)
        for (int k = 0; k < 3; ++k)
          for (int a = 0; a < 3; ++a) blk.v[k][a][l] = tris[blk.first + l].v[3 * k + a];
      blocks.push_back(blk);
    }
    return start;
  }

  // Fills node `self` from binary node b. The interior children of a node are allocated next to each
  // other (then filled depth first), so siblings share DRAM pages and the adjacent-line prefetch.
  void collapse(std::uint32_t self, std::uint32_t b, int level) {
    depth = std::max(depth, level);
    std::uint32_t kids[4];
    int nk = 0;
    if (as_leaf(b)) {
      kids[nk++] = b;  // only for a small root
    } else {
      kids[nk++] = bin[b].first;
      kids[nk++] = bin[b].first + 1;
      while (nk < 4) {
        int pick = -1;
        float best = -1.f;
        for (int i = 0; i < nk; ++i) {
          if (as_leaf(kids[i])) continue;
          const float a = node_area(bin[kids[i]]);
          if (a > best) { best = a; pick = i; }
        }
        if (pick < 0) break;
        const std::uint32_t c = bin[kids[pick]].first;
        kids[pick] = c;  // keep left-to-right order of the binary tree
        for (int j = nk; j > pick + 1; --j) kids[j] = kids[j - 1];
        kids[pick + 1] = c + 1;
        ++nk;
      }
    }
    Bvh4Node node{};
    for (int i = 0; i < 4; ++i) {
      if (i >= nk) {
        for (int a = 0; a < 3; ++a) {
          node.box[2 * a][i] = std::numeric_limits<float>::infinity();
          node.box[2 * a + 1][i] = -std::numeric_limits<float>::infinity();
        }
        node.child[i] = 0;
        node.count[i] = 0;
        continue;
      }
      const BvhNode& c = bin[kids[i]];
      for (int a = 0; a < 3; ++a) { node.box[2 * a][i] = c.lo[a]; node.box[2 * a + 1][i] = c.hi[a]; }
      if (as_leaf(kids[i])) {
        node.count[i] = hi[kids[i]] - lo[kids[i]];
        node.child[i] = add_blocks(lo[kids[i]], node.count[i]);
      } else {
        node.count[i] = 0;
        node.child[i] = static_cast<std::uint32_t>(out.size());
        out.emplace_back();
      }
    }
    out[self] = node;
    for (int i = 0; i < nk; ++i)
      if (node.count[i] == 0) collapse(node.child[i], kids[i], level + 1);
  }
};

}  // namespace

Bvh4 collapse_bvh4(const Bvh& bvh, const std::vector<TriRecord>& tris) {
  if (bvh.nodes.empty()) throw std::invalid_argument("cannot collapse an empty BVH");
  Bvh4 out;
  out.nodes.reserve(bvh.nodes.size() / 3 + 1);
  out.blocks.reserve(static_cast<std::size_t>(bvh.leaf_count) + 1);
  Collapser c{bvh.nodes, tris, out.nodes, out.blocks, 0, {}, {}};
  c.lo.resize(bvh.nodes.size());
  c.hi.resize(bvh.nodes.size());
  c.ranges(0);
  out.nodes.emplace_back();
  c.collapse(0, 0, 0);
  out.depth = c.depth;
  return out;
}

}  // namespace sim_core
