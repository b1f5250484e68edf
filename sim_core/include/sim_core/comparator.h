// Compute-on-demand comparator (thesis ch. 4): an asynchronous comparator decides a comparison as soon as
// it meets the first differing bit from the MSB, so its delay and energy depend on the length of the
// leading run of equal bits (the "compute chain") of the two operands.
#pragma once
#include <array>
#include <cstdint>
#include <cstring>

namespace sim_core {

// Bits of a hit distance the modelled comparator sees: the thesis prices a 24-bit comparator, and the
// top 24 bits of a non-negative IEEE float (sign, exponent, 15 mantissa bits) order like the float.
inline constexpr int kComparatorBits = 24;
using ComparatorHistogram = std::array<std::uint64_t, kComparatorBits + 1>;

// Length of the leading run of equal bits of two non-negative floats, over the top kComparatorBits bits;
// equal operands give the full width.
inline int comparator_chain_length(float a, float b) {
  std::uint32_t ua = 0, ub = 0;
  std::memcpy(&ua, &a, sizeof ua);
  std::memcpy(&ub, &b, sizeof ub);
  const std::uint32_t diff = (ua ^ ub) >> (32 - kComparatorBits);
  if (diff == 0) return kComparatorBits;
  return __builtin_clz(diff) - (32 - kComparatorBits);
}

}  // namespace sim_core
