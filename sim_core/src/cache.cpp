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
    const std::uint32_t sets = config_.size_bytes / (config_.line_bytes * config_.ways);
    set_mask_ = sets - 1;
    while ((1u << line_shift_) < config_.line_bytes) ++line_shift_;
    lines_.assign(static_cast<std::size_t>(sets) * config_.ways, ~std::uint64_t{0});
  }
}

void CacheModel::reset() {
  std::fill(lines_.begin(), lines_.end(), ~std::uint64_t{0});
  stats_ = {};
}

}  // namespace sim_core
