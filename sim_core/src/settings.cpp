#include "sim_core/settings.h"

#include <cmath>
#include <stdexcept>

namespace sim_core {

void RenderSettings::validate() const {
  const int m = static_cast<int>(mode);
  if (m < 0 || m > 3) throw std::invalid_argument("mode must be 1spp, fsaa, undersample or supersample");
  if (block < 2 || block > 4) throw std::invalid_argument("block must be 2, 3 or 4");
  if (!std::isfinite(normal_threshold_deg) || normal_threshold_deg > 180.f)
    throw std::invalid_argument("normal_threshold_deg must be finite and <= 180");
  if (max_depth < 0 || max_depth > 4) throw std::invalid_argument("max_depth must be in 0..4");
  if (shadow_samples < 0 || shadow_samples > 256) throw std::invalid_argument("shadow_samples must be in 0..256");
  if (!(resolution_scale >= 0.25f && resolution_scale <= 1.f))
    throw std::invalid_argument("resolution_scale must be in [0.25, 1]");
  const int e = static_cast<int>(env_filter);
  if (e < 0 || e > 2) throw std::invalid_argument("env_filter must be off, box or bartlett");
  if (ao_samples < 0 || ao_samples > 256) throw std::invalid_argument("ao_samples must be in 0..256");
  if (!std::isfinite(ao_distance) || ao_distance < 0.f) throw std::invalid_argument("ao_distance must be >= 0");
  if (!(multirate_low >= 0.f && multirate_high <= 1.f && multirate_low < multirate_high))
    throw std::invalid_argument("multirate thresholds need 0 <= low < high <= 1");
  if (tile_size < 4 || tile_size > 256) throw std::invalid_argument("tile_size must be in 4..256");
}

}  // namespace sim_core
