#include "sim_core/streaming.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace sim_core {
namespace {

struct CountingRecorder {
  TraversalTraffic* t;
  CacheModel* cache;
  void node(std::uint32_t i) {
    ++t->node_fetches;
    ++t->box_tests;
    if (cache) cache->access(kNodeBaseAddress + std::uint64_t{i} * sizeof(BvhNode), sizeof(BvhNode));
  }
  void tri(std::uint32_t i) {
    ++t->triangle_fetches;
    ++t->triangle_tests;
    if (cache) cache->access(kTriBaseAddress + std::uint64_t{i} * sizeof(TriRecord), sizeof(TriRecord));
  }
  void compare(float candidate, float best) {
    const int c = comparator_chain_length(std::fabs(candidate), best);
    ++t->compare_all[static_cast<std::size_t>(c)];
    if (best < kInf) ++t->compare_finite[static_cast<std::size_t>(c)];
  }
};

struct Elem {
  std::uint32_t ray;
  float entry;
};

struct Work {
  std::uint32_t node;
  std::vector<Elem> stream;
};

void check_rays(const Ray* rays, std::size_t n, const Hit* hits) {
  if (n > 0 && (rays == nullptr || hits == nullptr)) throw std::invalid_argument("null ray or hit buffer");
  if (n > 0xFFFFFFFFull) throw std::invalid_argument("too many rays for one stream");
}

}  // namespace

TraversalTraffic per_ray_traversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits,
                                   const CacheConfig& cache, std::size_t group_size) {
  check_rays(rays, n, hits);
  TraversalTraffic t;
  t.rays = n;
  if (cache.enabled()) {
    if (group_size == 0) group_size = n;
    for (std::size_t start = 0; start < n; start += group_size) {
      CacheModel model(cache);
      CountingRecorder rec{&t, &model};
      const std::size_t end = std::min(n, start + group_size);
      for (std::size_t i = start; i < end; ++i) hits[i] = scene.closest(rays[i], rec);
      t.scene_dram_bytes += model.stats().dram_bytes;
    }
  } else {
    CountingRecorder rec{&t, nullptr};
    for (std::size_t i = 0; i < n; ++i) hits[i] = scene.closest(rays[i], rec);
  }
  t.node_bytes = t.node_fetches * sizeof(BvhNode);
  t.triangle_bytes = t.triangle_fetches * sizeof(TriRecord);
  if (!cache.enabled()) t.scene_dram_bytes = t.node_bytes + t.triangle_bytes;
  return t;
}

TraversalTraffic streaming_traversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits) {
  check_rays(rays, n, hits);
  TraversalTraffic t;
  t.rays = n;
  const std::vector<BvhNode>& nodes = scene.bvh().nodes;
  std::vector<PreparedRay> prepared;
  prepared.reserve(n);
  std::vector<float> best(n);
  for (std::size_t i = 0; i < n; ++i) {
    prepared.emplace_back(rays[i]);
    best[i] = rays[i].tmax;
    hits[i] = Hit{};
  }
  if (n == 0 || nodes.empty()) return t;

  // Root: fetched once, every ray tested against its box.
  std::vector<Work> stack;
  Work root{0, {}};
  ++t.node_fetches;
  for (std::uint32_t i = 0; i < n; ++i) {
    ++t.box_tests;
    const float e = box_entry(nodes[0], prepared[i], rays[i].tmin, best[i]);
    if (e != kInf) root.stream.push_back({i, e});
  }
  t.stream_elements_written += root.stream.size();
  if (!root.stream.empty()) stack.push_back(std::move(root));

  std::vector<Elem> out0, out1;
  while (!stack.empty()) {
    Work w = std::move(stack.back());
    stack.pop_back();
    // Compaction at pop: drop rays whose closest hit moved in front of this node.
    std::size_t kept = 0;
    for (const Elem& e : w.stream) {
      if (e.entry < best[e.ray]) w.stream[kept++] = e;
    }
    t.culled_at_pop += w.stream.size() - kept;
    t.stream_elements_read += w.stream.size();  // the compaction pass reads every element once
    w.stream.resize(kept);
    if (w.stream.empty()) continue;
    const BvhNode& node = nodes[w.node];
    if (node.count == 0) {
      // Interior: one fetch of the sibling pair for the whole stream; two conditional output streams.
      const std::uint32_t c = node.first;
      t.node_fetches += 2;
      ++t.interior_streams;
      t.interior_stream_rays += w.stream.size();
      out0.clear();
      out1.clear();
      double sum0 = 0.0, sum1 = 0.0;
      for (const Elem& e : w.stream) {
        const Ray& r = rays[e.ray];
        t.box_tests += 2;
        const float t0 = box_entry(nodes[c], prepared[e.ray], r.tmin, best[e.ray]);
        const float t1 = box_entry(nodes[c + 1], prepared[e.ray], r.tmin, best[e.ray]);
        if (t0 != kInf) { out0.push_back({e.ray, t0}); sum0 += t0; }
        if (t1 != kInf) { out1.push_back({e.ray, t1}); sum1 += t1; }
      }
      t.stream_elements_written += out0.size() + out1.size();
      // Depth first, nearer child (by mean entry distance) on top so its hits cull the farther stream.
      const bool first0 = !out0.empty() && (out1.empty() || sum0 / out0.size() <= sum1 / out1.size());
      if (first0) {
        if (!out1.empty()) stack.push_back({c + 1, out1});
        stack.push_back({c, out0});
      } else {
        if (!out0.empty()) stack.push_back({c, out0});
        if (!out1.empty()) stack.push_back({c + 1, out1});
      }
    } else {
      // Leaf: its triangles fetched once, tested against every ray of the stream.
      ++t.leaf_streams;
      t.leaf_stream_rays += w.stream.size();
      const std::uint32_t end = node.first + node.count;
      t.triangle_fetches += node.count;
      for (std::uint32_t k = node.first; k < end; ++k) {
        const TriRecord& tri = scene.tri(k);
        for (const Elem& e : w.stream) {
          ++t.triangle_tests;
          float tt, b0, b1, b2;
          bool compared = false;
          if (intersect_triangle(tri, prepared[e.ray], rays[e.ray].tmin, best[e.ray], &tt, &b0, &b1, &b2,
                                 &compared)) {
            best[e.ray] = tt;
            Hit& h = hits[e.ray];
            h.t = tt; h.tri = k; h.b0 = b0; h.b1 = b1; h.b2 = b2;
          }
        }
      }
    }
  }
  t.node_bytes = t.node_fetches * sizeof(BvhNode);
  t.triangle_bytes = t.triangle_fetches * sizeof(TriRecord);
  t.scene_dram_bytes = t.node_bytes + t.triangle_bytes;
  t.stream_bytes = (t.stream_elements_read + t.stream_elements_written) * kStreamElementBytes +
                   t.stream_elements_read * kRayRecordBytes;
  return t;
}

}  // namespace sim_core
