// Compute-chain length of the 24-bit comparator: exact cases and the analytic law on random operands.
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "sim_core/comparator.h"

#include "check.h"

using sim_core::comparator_chain_length;


static float from_bits(std::uint32_t u) { float f; std::memcpy(&f, &u, sizeof f); return f; }

int main() {
  CHECK(comparator_chain_length(1.0f, 1.0f) == 24);
  // 1.0 = 0x3F800000 and 2.0 = 0x40000000 differ at the first bit below the sign.
  CHECK(comparator_chain_length(1.0f, 2.0f) == 0);
  // Same exponent, mantissa differs at its top bit: 8 exponent bits equal.
  CHECK(comparator_chain_length(1.0f, 1.5f) == 8);
  // A difference only in the lowest 7 mantissa bits is invisible to a 24-bit comparator.
  CHECK(comparator_chain_length(from_bits(0x3F800000u), from_bits(0x3F80007Fu)) == 24);
  CHECK(comparator_chain_length(from_bits(0x3F800000u), from_bits(0x3F800080u)) == 23);
  CHECK(comparator_chain_length(1.0f, INFINITY) == 0);  // exponent 0x7F vs 0xFF differs at its top bit
  CHECK(comparator_chain_length(3.0f, INFINITY) == 1);  // 0x404.. vs 0x7F8..
  // Uniformly random operands: P(chain >= k) = 2^-k.
  std::mt19937 rng(12345);
  const int n = 1 << 20;
  long long ge[26] = {0};
  for (int i = 0; i < n; ++i) {
    const int c = comparator_chain_length(from_bits(rng() & 0x7FFFFFFFu), from_bits(rng() & 0x7FFFFFFFu));
    for (int k = 0; k <= c; ++k) ++ge[k];
  }
  for (int k = 0; k <= 10; ++k) {
    const double p = std::ldexp(1.0, -k);
    const double sd = std::sqrt(p * (1 - p) / n);
    const double got = static_cast<double>(ge[k]) / n;
    if (std::fabs(got - p) > 5 * sd + 1e-12) {
      std::fprintf(stderr, "k=%d P(chain>=k)=%g expected %g\n", k, got, p);
      ++check_failures();
    }
  }
  return check_exit_code();
}
