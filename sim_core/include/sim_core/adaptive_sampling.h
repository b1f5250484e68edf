// Adaptive sampling: the sampling schedule inside one tile (tracer seed sec. 3). Samples are pixels
// (1 spp, undersampling) or sub-pixels of a k x k grid (FSAA, supersampling). Reference samples R sit every
// `spacing` samples along X and Y (plus the tile's last row and column); they are traced first. Then,
// first along X on the R rows and then along Y on every column, each run of intermediate samples between
// two adjacent known samples is interpolated when the two pass the similarity test (same object, normals
// within the threshold, same shadow bits, and the same for their first reflection/refraction hits) and
// traced otherwise. Multi-rate control picks each tile's spacing from the previous frame.
#pragma once
#include "sim_core/render.h"
#include "sim_core/shader.h"

namespace sim_core {

// True when two samples may be interpolated between.
bool similar(const SampleGeometry& a, const SampleGeometry& b, float cos_threshold);

// Block size a tile uses this frame under multi-rate control: coarser when the previous frame's
// similarity ratio reached `high`, finer when it fell below `low`, unchanged in between (hysteresis).
int multirate_block(int previous_block, float previous_ratio, std::uint64_t previous_checks,
                    const RenderSettings& settings);

// Renders the tile at pixel rect [x0, x0 + w) x [y0, y0 + h) into `fb` with reference spacing `spacing`
// (1 = trace every sample) on a k x k sub-pixel grid; fills `stat`. With a multi-sample buffer in `fb`
// (k > 1) the tile writes its sub-samples there, and a tile on the frame's edge also traces the guard
// sub-samples beyond it that the pixel filter reads. With `part` (a rectangle of the tile's pixels, in the
// same coordinates), only that part is written to `fb`, each of its samples as the whole tile has it: the
// tile is traced only where they depend on it (at full rate the part's own samples; adaptively the
// reference cells holding them), so the tile's statistics then cover that work. The tile itself may reach
// beyond `fb` (an apron tile of a window, render.h); `part` may not.
void render_tile(TileContext& ctx, FrameBuffers& fb, int x0, int y0, int w, int h, int k, int spacing,
                 TileStat* stat, const PixelRect* part = nullptr);

}  // namespace sim_core
