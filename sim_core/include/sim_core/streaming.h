// Streaming ray traversal (thesis ch. 3) against per-ray traversal: memory traffic per frame.
//
// Per-ray traversal is what the tracer does: each ray walks the 4-wide BVH on its own, fetching every node
// (128 bytes, four child boxes) and triangle it visits. Streaming traversal pushes a whole stream of rays
// through the same tree node by node: a work stack holds (node, ray stream) pairs; an interior node is
// fetched ONCE for the whole stream, every ray is tested against its four child boxes, and the rays that
// enter a child are compacted into that child's conditional output stream (no masks, thesis sec. 3.1.2); a
// leaf's triangles are fetched once and tested against every ray of its stream. Before a stream is
// processed, rays whose entry distance is no longer in front of their closest hit are dropped (compaction
// again). The thesis uses a kd-tree with kd-restart; over our BVH a depth-first stack of streams plays the
// restart stream's role (no ray re-enters the root). Both modes use the same box and watertight triangle
// tests, so they find the same closest hits.
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/cache.h"
#include "sim_core/comparator.h"
#include "sim_core/intersect.h"
#include "sim_core/scene.h"

namespace sim_core {

struct TraversalTraffic {
  std::uint64_t rays = 0;
  std::uint64_t node_fetches = 0;      // 4-wide BVH nodes read (128 B each)
  std::uint64_t triangle_fetches = 0;  // triangle records read (48 B each)
  std::uint64_t node_bytes = 0;
  std::uint64_t triangle_bytes = 0;
  std::uint64_t scene_dram_bytes = 0;  // node + triangle bytes that reach DRAM (after the cache, if any)
  std::uint64_t box_tests = 0;         // ray-box tests (four per node fetch and ray)
  std::uint64_t triangle_tests = 0;    // ray-triangle tests
  // Streaming only: ray-stream traffic (each stream element is read once by the kernel that consumes it
  // and written once into each output stream it enters), and stream statistics.
  std::uint64_t stream_elements_read = 0;
  std::uint64_t stream_elements_written = 0;
  std::uint64_t stream_bytes = 0;      // (read + written) * kStreamElementBytes
  std::uint64_t interior_streams = 0, leaf_streams = 0;
  std::uint64_t interior_stream_rays = 0, leaf_stream_rays = 0;  // sums, for average stream lengths
  std::uint64_t culled_at_pop = 0;     // rays compacted away because their closest hit is nearer
  // Per-ray only: compute-chain lengths of the closest-hit comparisons (candidate t against the current
  // best), all of them and only those against a finite best (not the initial +inf of a ray's first hit).
  ComparatorHistogram compare_all{};
  ComparatorHistogram compare_finite{};
};

// One stream element: ray id + its entry distance into the stream's node (the ray's origin, direction and
// current closest distance sit in a ray buffer the element indexes: 28 B read per element processed).
inline constexpr std::uint32_t kStreamElementBytes = 8;
inline constexpr std::uint32_t kRayRecordBytes = 28;

// Per-ray traversal of `n` rays. With `cache` enabled, rays are split into consecutive groups of
// `group_size` rays (the tracer's tiles), each with its own cold cache, and scene_dram_bytes counts misses;
// otherwise every fetch goes to memory.
TraversalTraffic per_ray_traversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits,
                                   const CacheConfig& cache = {}, std::size_t group_size = 0);

// Streaming traversal of all `n` rays as one stream (one frame's rays of one generation).
TraversalTraffic streaming_traversal(const Scene& scene, const Ray* rays, std::size_t n, Hit* hits);

}  // namespace sim_core
