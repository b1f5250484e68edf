#include "sim_core/cache.h"

#include <algorithm>
#include <stdexcept>

namespace sim_core {
namespace {
bool is_pow2(std::uint32_t v) { return v != 0 && (v & (v - 1)) == 0; }
}  // namespace

void CacheConfig::validate() const {
  if (!enabled()) return;
  if (!is_pow2(line_bytes) || !is_pow2(ways) || !is_pow2(size_bytes))
    throw std::invalid_argument("cache size, line size and ways must be powers of two");
  if (size_bytes < line_bytes * ways)
    throw std::invalid_argument("cache must hold at least one set (size >= line * ways)");
}

CacheModel::CacheModel(const CacheConfig& config) : config_(config) {
  config_.validate();
  if (config_.enabled()) {
    sets_ = config_.size_bytes / (config_.line_bytes * config_.ways);
    while ((1u << line_shift_) < config_.line_bytes) ++line_shift_;
    tags_.assign(static_cast<std::size_t>(sets_) * config_.ways, ~std::uint64_t{0});
    last_use_.assign(tags_.size(), 0);
  }
}

void CacheModel::reset() {
  std::fill(tags_.begin(), tags_.end(), ~std::uint64_t{0});
  std::fill(last_use_.begin(), last_use_.end(), 0);
  clock_ = 0;
  stats_ = {};
}

void CacheModel::access(std::uint64_t address, std::uint32_t bytes) {
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
  for (std::uint64_t line = first; line <= last; ++line) {
    ++stats_.accesses;
    ++clock_;
    const std::size_t set = static_cast<std::size_t>(line % sets_);
    std::uint64_t* tags = &tags_[set * config_.ways];
    std::uint64_t* use = &last_use_[set * config_.ways];
    std::uint32_t victim = 0;
    bool hit = false;
    for (std::uint32_t w = 0; w < config_.ways; ++w) {
      if (tags[w] == line) { use[w] = clock_; hit = true; break; }
      if (use[w] < use[victim]) victim = w;
    }
    if (!hit) {
      ++stats_.misses;
      stats_.dram_bytes += config_.line_bytes;
      tags[victim] = line;
      use[victim] = clock_;
    }
  }
}

}  // namespace sim_core
