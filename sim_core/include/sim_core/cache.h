// Set-associative cache model (LRU) for BVH-node and triangle fetches of the traversal-and-intersection
// unit; its misses become DRAM bytes in the energy model. Deterministic: one model per tile, cold at the
// tile's start, so results do not depend on which thread renders which tile.
#pragma once
#include <cstdint>
#include <vector>

namespace sim_core {

struct CacheConfig {
  std::uint32_t size_bytes = 0;  // 0 disables the model (every fetch goes to DRAM)
  std::uint32_t line_bytes = 64;
  std::uint32_t ways = 4;
  bool enabled() const { return size_bytes > 0; }
  void validate() const;  // throws std::invalid_argument on a geometry that is not a power of two
};

struct CacheStats {
  std::uint64_t accesses = 0;  // line accesses
  std::uint64_t misses = 0;
  std::uint64_t dram_bytes = 0;
  CacheStats& operator+=(const CacheStats& o) {
    accesses += o.accesses; misses += o.misses; dram_bytes += o.dram_bytes;
    return *this;
  }
};

class CacheModel {
 public:
  explicit CacheModel(const CacheConfig& config);
  // Touches every line that [address, address + bytes) spans.
  void access(std::uint64_t address, std::uint32_t bytes);
  const CacheStats& stats() const { return stats_; }
  void reset();

 private:
  CacheConfig config_;
  std::uint32_t sets_ = 0;
  std::uint32_t line_shift_ = 0;
  std::uint64_t clock_ = 0;
  std::vector<std::uint64_t> tags_;      // sets_ * ways, ~0 = invalid
  std::vector<std::uint64_t> last_use_;  // LRU timestamps
  CacheStats stats_;
};

}  // namespace sim_core
