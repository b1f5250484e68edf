#include "sim_core/streaming.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace sim_core {
namespace {

// Per-ray traversal as the tracer does it (4-wide nodes: four box tests per node fetch).
struct CountingRecorder {
  TraversalTraffic* t;
  CacheModel* cache;
  void node(std::uint32_t i, std::uint32_t bytes) {
    ++t->node_fetches;
    t->box_tests += kBoxesPerNodeStep;
    if (cache) cache->access(kNodeBaseAddress + std::uint64_t{i} * bytes, bytes);
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

// A node of the 4-wide tree and the rays that entered it: an interior node (count 0, `child` = node index)
// or a leaf (`count` triangles in blocks from `child` on).
struct Work {
  std::uint32_t child, count;
  std::vector<Elem> stream;
};

void check_rays(const Ray* rays, std::size_t n, const Hit* hits) {
  if (n > 0 && (rays == nullptr || hits == nullptr)) throw std::invalid_argument("null ray or hit buffer");
  if (n > 0xFFFFFFFFull) throw std::invalid_argument("too many rays for one stream");
}

// Node and triangle bytes of the fetches counted so far.
void count_fetch_bytes(TraversalTraffic* t) {
  t->node_bytes = t->node_fetches * sizeof(Bvh4Node);
  t->triangle_bytes = t->triangle_fetches * sizeof(TriRecord);
}

// One stream of rays pushed through the 4-wide BVH node by node (streaming.h): a depth-first stack of
// (node, ray stream) work items, compacted at every pop.
class StreamTraversal {
 public:
  StreamTraversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits, TraversalTraffic* t)
      : scene_(scene), bvh_(scene.bvh4()), rays_(rays), hits_(hits), t_(*t) {
    prepared_.reserve(n);
    prepared4_.reserve(n);
    best_.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      prepared_.emplace_back(rays[i]);
      prepared4_.emplace_back(prepared_.back(), rays[i].tmin);
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
      if (w.count == 0) {
        split_interior(w);
      } else {
        intersect_leaf(w);
      }
    }
  }

 private:
  const Scene& scene_;
  const Bvh4& bvh_;
  const Ray* rays_;
  Hit* hits_;
  TraversalTraffic& t_;
  std::vector<PreparedRay> prepared_;
  std::vector<PreparedRay4> prepared4_;
  std::vector<float> best_;  // closest hit so far per ray (its tmax at the start)
  std::vector<Work> stack_;
  std::vector<Elem> out_[4];

  // The root is visited by every ray (as the per-ray walk does): its stream holds them all.
  void push_root() {
    Work root{0, 0, {}};
    root.stream.reserve(prepared_.size());
    for (std::uint32_t i = 0; i < prepared_.size(); ++i) root.stream.push_back({i, -kInf});
    t_.stream_elements_written += root.stream.size();
    if (!root.stream.empty()) stack_.push_back(std::move(root));
  }

  // Compaction at pop: drops rays whose closest hit moved in front of this node. False when none is left.
  bool compact(Work* w) {
    std::size_t kept = 0;
    for (const Elem& e : w->stream) {
      if (e.entry <= best_[e.ray] * kSlabRobust) w->stream[kept++] = e;  // ClosestHitQuery::skip's test
    }
    t_.culled_at_pop += w->stream.size() - kept;
    t_.stream_elements_read += w->stream.size();  // the compaction pass reads every element once
    w->stream.resize(kept);
    return !w->stream.empty();
  }

  // Interior: one fetch of the node (its four child boxes) for the whole stream; one conditional output
  // stream per child, pushed depth first nearest (by mean entry distance) on top so its hits cull the
  // farther streams. The order is the per-ray walk's (same sort), so a one-ray stream visits what the ray
  // would.
  void split_interior(const Work& w) {
    const Bvh4Node& node = bvh_.nodes[w.child];
    ++t_.node_fetches;
    ++t_.interior_streams;
    t_.interior_stream_rays += w.stream.size();
    double sum[4] = {0.0, 0.0, 0.0, 0.0};
    for (auto& o : out_) o.clear();
    for (const Elem& e : w.stream) {
      t_.box_tests += kBoxesPerNodeStep;
      alignas(16) float tn[4];
      const int mask = box_entry4(node, prepared_[e.ray], prepared4_[e.ray], rays_[e.ray].tmin, best_[e.ray], tn);
      for (int c = 0; c < 4; ++c) {
        if (!(mask & (1 << c))) continue;
        out_[c].push_back({e.ray, tn[c]});
        sum[c] += tn[c];
      }
    }
    struct Child { int index; double mean; };
    Child order[4];
    int nh = 0;
    for (int c = 0; c < 4; ++c) {
      if (out_[c].empty()) continue;
      t_.stream_elements_written += out_[c].size();
      const Child ch{c, sum[c] / static_cast<double>(out_[c].size())};
      int j = nh++;
      while (j > 0 && order[j - 1].mean < ch.mean) { order[j] = order[j - 1]; --j; }  // descending
      order[j] = ch;
    }
    for (int k = 0; k < nh; ++k) {
      const int c = order[k].index;
      stack_.push_back({node.child[c], node.count[c], out_[c]});
    }
  }

  // Leaf: its triangles fetched once, each tested against every ray of the stream.
  void intersect_leaf(const Work& w) {
    ++t_.leaf_streams;
    t_.leaf_stream_rays += w.stream.size();
    const std::uint32_t first = bvh_.blocks[w.child].first, end = first + w.count;
    t_.triangle_fetches += w.count;
    for (std::uint32_t k = first; k < end; ++k) {
      const TriRecord& tri = scene_.tri(k);
      for (const Elem& e : w.stream) {
        ++t_.triangle_tests;
        float tt, b0, b1, b2;
        bool compared = false;
        Hit& h = hits_[e.ray];
        if (intersect_triangle(tri, prepared_[e.ray], rays_[e.ray].tmin, closest_limit(best_[e.ray], h.tri, k), &tt,
                               &b0, &b1, &b2, &compared)) {
          best_[e.ray] = tt;
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
  if (n == 0 || scene.bvh4().nodes.empty()) return t;
  traversal.run();
  count_fetch_bytes(&t);
  t.scene_dram_bytes = t.node_bytes + t.triangle_bytes;
  t.stream_bytes = (t.stream_elements_read + t.stream_elements_written) * kStreamElementBytes +
                   t.stream_elements_read * kRayRecordBytes;
  return t;
}

}  // namespace sim_core
