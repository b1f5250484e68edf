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
  CacheConfig config_;
  std::uint64_t set_mask_ = 0;  // sets - 1 (the set count is a power of two)
  std::uint32_t line_shift_ = 0;
  // Each set's resident lines, most recently used first (~0 = empty way, always at the end): a hit moves
  // its line to the front, a miss drops the last one (true LRU without timestamps).
  std::vector<std::uint64_t> lines_;  // sets * ways
  CacheStats stats_;

  void access_line(std::uint64_t line) {
    ++stats_.accesses;
    std::uint64_t* set = &lines_[static_cast<std::size_t>(line & set_mask_) * config_.ways];
    if (set[0] == line) return;  // already the most recently used line of its set
    std::uint32_t w = 1;
    while (w < config_.ways && set[w] != line) ++w;
    if (w == config_.ways) {  // miss: the least recently used (or an empty) way goes
      ++stats_.misses;
      stats_.dram_bytes += config_.line_bytes;
      w = config_.ways - 1;
    }
    for (; w > 0; --w) set[w] = set[w - 1];
    set[0] = line;
  }
};

}  // namespace sim_core
