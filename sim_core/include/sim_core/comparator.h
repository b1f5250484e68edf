// Compute-on-demand comparator (thesis ch. 4): an asynchronous comparator decides a comparison as soon as
// it meets the first differing bit from the MSB, so its delay and energy depend on the length of the
// leading run of equal bits (the "compute chain") of the two operands.
#pragma once
#include <array>
#include <cstdint>
#include <cstring>

namespace sim_core {

// Bits of a hit distance the modelled comparator sees. The thesis prices a 24-bit comparator (Table 4.1).
// Hit distances are non-negative, so the IEEE sign bit carries no information and is not fed to it: the
// comparator sees the 24 bits below the sign (8 exponent bits, the top 16 mantissa bits), which order
// like the float itself for non-negative values (including +inf, the "no hit yet" distance).
inline constexpr int kComparatorBits = 24;
using ComparatorHistogram = std::array<std::uint64_t, kComparatorBits + 1>;

// Length of the leading run of equal bits of two non-negative floats over those kComparatorBits bits,
// i.e. the number of bits after the first one that the comparator must examine (the "compute chain" of
// Table 4.1); equal operands (over those bits) give kComparatorBits.
inline int comparator_chain_length(float a, float b) {
  std::uint32_t ua = 0, ub = 0;
  std::memcpy(&ua, &a, sizeof ua);
  std::memcpy(&ub, &b, sizeof ub);
  const std::uint32_t diff = ((ua ^ ub) << 1) >> (32 - kComparatorBits);
  if (diff == 0) return kComparatorBits;
  return __builtin_clz(diff) - (32 - kComparatorBits);
}

}  // namespace sim_core
