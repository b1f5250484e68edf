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

// Node and triangle bytes of the fetches counted so far.
void count_fetch_bytes(TraversalTraffic* t) {
  t->node_bytes = t->node_fetches * sizeof(BvhNode);
  t->triangle_bytes = t->triangle_fetches * sizeof(TriRecord);
}

// One stream of rays pushed through the BVH node by node (streaming.h): a depth-first stack of
// (node, ray stream) work items, compacted at every pop.
class StreamTraversal {
 public:
  StreamTraversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits, TraversalTraffic* t)
      : scene_(scene), nodes_(scene.bvh().nodes), rays_(rays), hits_(hits), t_(*t) {
    prepared_.reserve(n);
    best_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      prepared_.emplace_back(rays[i]);
      best_[i] = rays[i].tmax;
      hits[i] = Hit{};
    }
  }

  void run() {
    push_root();
    while (!stack_.empty()) {
      Work w = std::move(stack_.back());
      stack_.pop_back();
      if (!compact(&w)) continue;
      const BvhNode& node = nodes_[w.node];
      if (node.count == 0) {
        split_interior(node, w);
      } else {
        intersect_leaf(node, w);
      }
    }
  }

 private:
  const Scene& scene_;
  const std::vector<BvhNode>& nodes_;
  const Ray* rays_;
  Hit* hits_;
  TraversalTraffic& t_;
  std::vector<PreparedRay> prepared_;
  std::vector<float> best_;  // closest hit so far per ray (its tmax at the start)
  std::vector<Work> stack_;
  std::vector<Elem> out0_, out1_;

  // Entry distance of ray `ray` into node `node` within its current interval (inf: missed).
  float entry(std::uint32_t node, std::uint32_t ray) const {
    return box_entry(nodes_[node], prepared_[ray], rays_[ray].tmin, best_[ray]);
  }

  // Root: fetched once, every ray tested against its box.
  void push_root() {
    Work root{0, {}};
    ++t_.node_fetches;
    for (std::uint32_t i = 0; i < prepared_.size(); ++i) {
      ++t_.box_tests;
      const float e = entry(0, i);
      if (e != kInf) root.stream.push_back({i, e});
    }
    t_.stream_elements_written += root.stream.size();
    if (!root.stream.empty()) stack_.push_back(std::move(root));
  }

  // Compaction at pop: drops rays whose closest hit moved in front of this node. False when none is left.
  bool compact(Work* w) {
    std::size_t kept = 0;
    for (const Elem& e : w->stream) {
      if (e.entry < best_[e.ray]) w->stream[kept++] = e;
    }
    t_.culled_at_pop += w->stream.size() - kept;
    t_.stream_elements_read += w->stream.size();  // the compaction pass reads every element once
    w->stream.resize(kept);
    return !w->stream.empty();
  }

  // Interior: one fetch of the sibling pair for the whole stream; two conditional output streams, pushed
  // depth first with the nearer child (by mean entry distance) on top so its hits cull the farther stream.
  void split_interior(const BvhNode& node, const Work& w) {
    const std::uint32_t c = node.first;
    t_.node_fetches += 2;
    ++t_.interior_streams;
    t_.interior_stream_rays += w.stream.size();
    out0_.clear();
    out1_.clear();
    double sum0 = 0.0, sum1 = 0.0;
    for (const Elem& e : w.stream) {
      t_.box_tests += 2;
      const float t0 = entry(c, e.ray);
      const float t1 = entry(c + 1, e.ray);
      if (t0 != kInf) { out0_.push_back({e.ray, t0}); sum0 += t0; }
      if (t1 != kInf) { out1_.push_back({e.ray, t1}); sum1 += t1; }
    }
    t_.stream_elements_written += out0_.size() + out1_.size();
    const bool first0 = !out0_.empty() && (out1_.empty() || sum0 / out0_.size() <= sum1 / out1_.size());
    if (first0) {
      if (!out1_.empty()) stack_.push_back({c + 1, out1_});
      stack_.push_back({c, out0_});
    } else {
      if (!out0_.empty()) stack_.push_back({c, out0_});
      if (!out1_.empty()) stack_.push_back({c + 1, out1_});
    }
  }

  // Leaf: its triangles fetched once, each tested against every ray of the stream.
  void intersect_leaf(const BvhNode& node, const Work& w) {
    ++t_.leaf_streams;
    t_.leaf_stream_rays += w.stream.size();
    const std::uint32_t end = node.first + node.count;
    t_.triangle_fetches += node.count;
    for (std::uint32_t k = node.first; k < end; ++k) {
      const TriRecord& tri = scene_.tri(k);
      for (const Elem& e : w.stream) {
        ++t_.triangle_tests;
        float tt, b0, b1, b2;
        bool compared = false;
        if (intersect_triangle(tri, prepared_[e.ray], rays_[e.ray].tmin, best_[e.ray], &tt, &b0, &b1, &b2,
                               &compared)) {
          best_[e.ray] = tt;
          Hit& h = hits_[e.ray];
          h.t = tt; h.tri = k; h.b0 = b0; h.b1 = b1; h.b2 = b2;
        }
      }
    }
  }
};

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
  count_fetch_bytes(&t);
  if (!cache.enabled()) t.scene_dram_bytes = t.node_bytes + t.triangle_bytes;
  return t;
}

TraversalTraffic streaming_traversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits) {
  check_rays(rays, n, hits);
  TraversalTraffic t;
  t.rays = n;
  StreamTraversal traversal(scene, rays, n, hits, &t);
  if (n == 0 || scene.bvh().nodes.empty()) return t;
  traversal.run();
  count_fetch_bytes(&t);
  t.scene_dram_bytes = t.node_bytes + t.triangle_bytes;
  t.stream_bytes = (t.stream_elements_read + t.stream_elements_written) * kStreamElementBytes +
                   t.stream_elements_read * kRayRecordBytes;
  return t;
}

}  // namespace sim_core
