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

// G-buffer prefetch of the error detection (counter gbuffer_prefetch_bytes = texels x kGBufferTexelBytes).
// Tiles are independent units of work on different cores, so each right-eye tile fetches, once, the block of
// left-eye G-buffer texels its pixels can reproject from: the left-eye pixels covered by the right tile's
// frustum between the nearest and farthest depth of the left samples that land in the right frame (plus
// the points at infinity when some of them saw the environment). For eyes shifted along the camera's right
// axis that is the tile's own rows and columns [x0 + f s / z_far, x0 + w + f s / z_near) (f = focal length
// in pixels, s = eye separation), clamped to the image: about h x (w + max disparity) texels, not full-width
// rows. Returns that texel count for the tile (x0, y0, w, h); 0 when no left sample lands in the frame.
std::uint64_t stereo_prefetch_texels(const Camera& left, const Camera& right, int x0, int y0, int w, int h,
                                     bool any_hit, float zmin, float zmax, bool any_env);

StereoOutput render_stereo(const Scene& scene, const Camera& left, const Camera& right,
                           const RenderSettings& settings, int threads, const MultirateState* previous,
                           const CacheConfig& cache, const TraceOptions& trace = {},
                           const CacheConfig& texture_cache = kDefaultTextureCache);

}  // namespace sim_core
