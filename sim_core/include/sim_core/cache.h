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
  // Touches every line that [address, address + bytes) spans. Inline: the tracer calls it for every node
  // and triangle fetch.
  void access(std::uint64_t address, std::uint32_t bytes) {
    if (bytes == 0) return;
    if (!config_.enabled()) {
      // No cache: every fetch is a DRAM read of whole 32-byte bursts.
      stats_.accesses += 1;
      stats_.misses += 1;
      stats_.dram_bytes += (bytes + 31u) / 32u * 32u;
      return;
    }
    const std::uint64_t first = address >> line_shift_;
    const std::uint64_t last = (address + bytes - 1) >> line_shift_;
    for (std::uint64_t line = first; line <= last; ++line) access_line(line);
  }
  const CacheStats& stats() const { return stats_; }
  void reset();

 private:
  struct Way {
    std::uint64_t tag;       // line number, ~0 = invalid
    std::uint64_t last_use;  // LRU timestamp (0 = never used)
  };
  CacheConfig config_;
  std::uint64_t set_mask_ = 0;  // sets - 1 (the set count is a power of two)
  std::uint32_t line_shift_ = 0;
  std::uint64_t clock_ = 0;
  // The line of the previous access: it is resident and already the most recently used line of its set,
  // so touching it again changes no replacement decision (same hits and misses as the full lookup).
  std::uint64_t last_line_ = ~std::uint64_t{0};
  std::vector<Way> ways_;  // sets * ways, one set's ways contiguous
  CacheStats stats_;

  void access_line(std::uint64_t line) {
    ++stats_.accesses;
    ++clock_;
    if (line == last_line_) return;
    last_line_ = line;
    Way* set = &ways_[static_cast<std::size_t>(line & set_mask_) * config_.ways];
    std::uint32_t victim = 0;
    for (std::uint32_t w = 0; w < config_.ways; ++w) {
      if (set[w].tag == line) { set[w].last_use = clock_; return; }
      if (set[w].last_use < set[victim].last_use) victim = w;
    }
    ++stats_.misses;
    stats_.dram_bytes += config_.line_bytes;
    set[victim] = {line, clock_};
  }
};

}  // namespace sim_core
