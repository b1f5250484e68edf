"""The frame-rate rule the store, its lookup and the optimiser share.

A store is priced for one target frame rate (its ``fps``). A setting *meets* it when its modelled frame
time fits in one frame period; a setting that misses it renders back to back at its own rate, so the
frame rate it reaches is the lower of the two (and its power is the full-speed power:
``sim_core.sustained_power`` prices power with the same test as ``EnergyReport.deadline_met``). The
optimiser ranks settings that meet the target ahead of those that miss it, a frontier keeps the ones
that miss it only in its slow tier (:mod:`.frontier`), and the lookup never picks a missing one while a
meeting one exists unless the query puts the budget first (:mod:`.lookup`; where the store keeps each
point's frame time at each pricing camera, "meets" is the prediction at the query's camera).
"""

from __future__ import annotations


def meets_frame_rate(frame_time_s: float, fps: float) -> bool:
    """Whether a frame of ``frame_time_s`` seconds keeps up with ``fps`` frames per second."""
    return frame_time_s <= 1.0 / fps


def frame_rate_reached(frame_time_s: float, fps: float) -> float:
    """The frame rate a GPU asked for ``fps`` reaches with frames of ``frame_time_s`` seconds."""
    return fps if frame_time_s <= 1.0 / fps else 1.0 / frame_time_s


def power_at_rate(power_w: float, frame_time_s: float, priced_fps: float, fps: float,
                  static_power_w: float) -> float:
    """The power of a setting priced for ``priced_fps`` (``power_w``, drawn at the rate it reached then)
    when ``fps`` frames per second are asked for instead.

    The dynamic energy of a frame is recovered from the priced power (P = P_static + E x rate reached)
    and drawn at the rate reached for ``fps``, as ``sim_core.sustained_power`` prices it; never above the
    full-speed power P_static + E / frame time."""
    dynamic_w = max(0.0, power_w - static_power_w)
    rate = frame_rate_reached(frame_time_s, priced_fps)
    energy_j = dynamic_w / rate
    if frame_time_s <= 0:
        return static_power_w + energy_j * fps
    return static_power_w + min(energy_j * frame_rate_reached(frame_time_s, fps), energy_j / frame_time_s)
