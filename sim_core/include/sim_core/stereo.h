// Stereo rendering by reprojection (stereo seed; Badt 1988): render the left eye, reproject its primary
// hit points into the right eye, reuse the left shading where the reprojection is valid and trace only the
// bad pixels: holes (disocclusion or out of frame), silhouettes (object or depth edges, where the side of
// the edge a pixel centre falls on differs between the eyes) and depth mismatches (a farther surface
// showing through a gap between two reprojected samples of one continuous nearer surface).
#pragma once
#include "sim_core/render.h"

namespace sim_core {

struct StereoOutput {
  RenderOutput left, right;
  double reuse_ratio = 0.0;  // reused right-eye pixels / right-eye pixels
  std::uint64_t holes = 0, silhouettes = 0, depth_mismatches = 0;
};

StereoOutput render_stereo(const Scene& scene, const Camera& left, const Camera& right,
                           const RenderSettings& settings, int threads, const MultirateState* previous,
                           const CacheConfig& cache);

}  // namespace sim_core
