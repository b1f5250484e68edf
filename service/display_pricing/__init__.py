"""Store figures at the path's display resolution: whole frames, or the tile estimator.

The search runs on small preview images; what a store records is priced again at the resolution the
path is shown at (DESIGN.md, fidelity rule). ``"full"`` renders every setting and the maximum-quality
reference as whole frames: exact, and as slow as the frames. ``"tiles"`` (the default) traces a sample
of the frame's blocks at display resolution and estimates the frame's error and activity counters
from it; power and frame time then come from the estimated counters through the energy model, as for
a rendered frame (never from a smaller render scaled by its pixel count). A job uses it for displays
of 1280x720 and more; smaller ones are priced as whole frames (``service.optimize.store_pricing``).

The tile estimator, for one camera and the settings priced there:

1. **Blocks.** The display frame is cut into ``block`` x ``block`` pixel blocks (64: four 16-pixel
   tiles a side). A setting's traced tiles belong to the block holding their centre (in display
   coordinates, so resolution scales below 1 map too); SSIM's local values belong to their pixel.
2. **Auxiliary frames.** Every setting and the reference are also rendered whole at 1/``aux_divisor``
   of the display size a side (1/16 of the pixels): their per-block error (1 - local SSIM) and per-tile
   counters, x_b, are known for every block.
3. **Sample.** Blocks are drawn with probability proportional to a size measure (mostly where the
   auxiliary frames of three fixed probe settings, the space's cheapest and two intermediate ones,
   differ from the reference; some where the reference's rays go; a floor everywhere), systematically
   along a serpentine path through the frame from a start drawn from the run's seed and the camera:
   a sample spread over the frame, the same for every setting of the camera (one reference), and the
   same whatever else is priced with it (cacheable per setting). A block with a size measure above the
   sampling interval is taken with certainty.
4. **Display-resolution values.** The sampled blocks are traced at display resolution as windows of
   the frame (``sim_core.render_window``: the frame's own pixels and per-tile counters; tiles are cold-
   cache units, so counters add exactly). SSIM needs half a window of margin around a block: the
   tiles whose centre lies in the block are traced whole (their counters are the sample's), the margin
   only where the SSIM reads it (a window keeps the frame's tile grid and traces a tile it cuts only
   over its part, as the frame has it). A window that goes through the resolve pass (FSAA,
   supersampling, AO) also traces an apron of the few pixels its filters read on each side, so the
   pixels are traced as few, large windows: the cheapest (aprons included) of bands of tile rows, bands
   of tile columns, the tiles' exact cover by rectangles (each window cut to the pixels it must cover)
   and the whole frame, so never more than a whole frame (``windows``). y_b = the block's sum of
   1 - local SSIM (an SSIM of the block and its margin, whose inner part is the block) and its tiles'
   counters.
5. **Ratio estimators.** Y = X * sum(y_b / pi_b) / sum(x_b / pi_b) over the sampled blocks, for the
   error sum and for each counter (pi_b the inclusion probabilities, X the auxiliary frame's total):
   the sample corrects the auxiliary frame's level, the auxiliary frame spreads the sample's values
   over the blocks not traced. Where the auxiliary total is 0 the plain Horvitz-Thompson sum is used.
   The pixel and frame-buffer counters are exact. An approximate standard error (with-replacement
   formula on the ratio's residuals) goes with each figure; the measured error against whole frames
   is in ``bench/RESULTS.md`` (``bench/bench_display_pricing.py``).

Only the SSIM metrics can be estimated from tiles; FLIP is priced on whole frames.

The package, by concept: ``config`` (the estimator's settings), ``sampling`` (blocks and the systematic
PPS sample), ``tracing`` (whole frames, auxiliary frames, display windows), ``windows`` (which windows to
trace), ``design`` (one camera's
sample and reference), ``estimator`` (the ratio estimators), ``camera`` (every setting at one camera),
``references`` (each camera's reference kept on disk between the builder's pricing rounds)
and ``pricer`` (the driver through the evaluation cache and executor).
"""

from service.display_pricing.camera import price_camera
from service.display_pricing.config import BLOCKS, ESTIMATOR_VERSION, ESTIMATORS, DisplayPricing
from service.display_pricing.pricer import DisplayPricer
from service.display_pricing.references import ReferenceStore
from service.display_pricing.sampling import (
    cover_rects,
    inclusion_probabilities,
    sample_start,
    serpentine,
    systematic_sample,
)
from service.display_pricing.tracing import AUX_TILE
from service.display_pricing.windows import apron_pixels, plan_windows, traced_area

__all__ = ["AUX_TILE", "BLOCKS", "ESTIMATORS", "ESTIMATOR_VERSION", "DisplayPricer", "DisplayPricing",
           "ReferenceStore", "apron_pixels", "cover_rects", "inclusion_probabilities", "plan_windows",
           "price_camera", "sample_start", "serpentine", "systematic_sample", "traced_area"]
