// Glossy filtering of an equirectangular environment map with summed-area tables (thesis ch. 2).
// A glossy reflection lobe is approximated by a cone around the reflected direction; the cone's footprint
// on the map is filtered in constant time: order 1 = box filter (first-order offset SAT, 4 reads per
// channel), order 2 = Bartlett filter (second-order offset SAT, 9 reads). sat.h explains the offset.
// Table precision (measured on a 2048x1024 HDR map against float64, see bench/RESULTS.md): a float32
// first-order offset table is within ~1 % for cones >= 0.03 rad, so the box filter uses float32 (the
// hardware-like choice); a float32 second-order table is unusable for cones < ~0.3 rad (its entries reach
// ~1e11, the 9-tap second difference loses every significant bit), so the Bartlett filter defaults to float64.
//
// Map convention (Blender/Cycles "Environment Texture", equirectangular, world frame Z up):
//   u = 0.5 - atan2(d.y, d.x) / (2 pi),  v = 1 - acos(d.z) / pi   (v = 1 at the top)
// Images are row 0 at the top, so pixel column = u * width, pixel row = acos(d.z) / pi * height.
// The map wraps horizontally; across a pole it continues on the opposite meridian (row -1-k at column c
// is row k at column c + width/2), which is where a footprint crossing the pole really lands.
#pragma once
#include <memory>
#include <vector>

#include "sim_core/math.h"
#include "sim_core/sat.h"

namespace sim_core {

// Continuous pixel coordinates (column in [0, width), row in [0, height]) of a direction (any length > 0).
void equirect_pixel(Vec3 direction, int width, int height, float* column, float* row);
// Unit direction of continuous pixel coordinates (inverse of equirect_pixel).
Vec3 equirect_direction(float column, float row, int width, int height);

class EnvironmentFilter {
 public:
  // Widest cone the filter supports; wider cones are clamped to it (a lobe this wide is nearly diffuse).
  static constexpr float kMaxConeHalfAngle = 0.7853981634f;  // pi / 4

  // rgb: (height, width, 3) float32 linear, row 0 at the top; copied. order in {1, 2}.
  // Throws std::invalid_argument on bad sizes/order or non-finite/negative values.
  // table_bits: 32 or 64 forces the table precision; 0 picks float32 for box and float64 for Bartlett.
  EnvironmentFilter(const float* rgb, int width, int height, int order, int table_bits = 0);

  // Mean radiance over the cone footprint of `direction` (need not be normalised; zero -> throws).
  // cone_half_angle <= 0 (or a footprint under one texel) returns the texel under the direction.
  Vec3 lookup(Vec3 direction, float cone_half_angle) const;
  // Unfiltered nearest-texel radiance (what a mirror reflection or a camera ray sees).
  Vec3 texel(Vec3 direction) const;

  int width() const { return width_; }
  int height() const { return height_; }
  int order() const { return order_; }
  int table_bits() const { return table_ ? 32 : 64; }
  // Table reads of the last kind of lookup: 4 per channel for box, 9 for Bartlett (for the energy model).
  int reads_per_lookup() const { return order_ == 1 ? 4 * 3 : 9 * 3; }

 private:
  int width_, height_, order_;
  int pad_x_, pad_y_;                       // wrapped columns / across-the-pole rows around the map
  std::vector<float> rgb_;                  // the map itself, for texel()
  std::unique_ptr<SummedAreaTable<float>> table_;     // built over the padded map (float32, the default)
  std::unique_ptr<SummedAreaTable<double>> table64_;  // or float64 (reference)
  void box_sum(int x0, int y0, int x1, int y1, double* out) const;
  void bartlett_sum(int cx, int cy, int rx, int ry, double* out) const;
};

}  // namespace sim_core
