// Textbook cases for the set-associative LRU cache model.
#include <cstdio>
#include <stdexcept>

#include "sim_core/cache.h"

#include "check.h"

using sim_core::CacheConfig;
using sim_core::CacheModel;


int main() {
  {  // A working set that fits: compulsory misses only, then every access hits.
    CacheModel c(CacheConfig{32768, 64, 4});
    for (int pass = 0; pass < 4; ++pass)
      for (std::uint64_t a = 0; a < 16384; a += 64) c.access(a, 64);
    CHECK(c.stats().accesses == 4u * 256u);
    CHECK(c.stats().misses == 256u);
    CHECK(c.stats().dram_bytes == 256u * 64u);
  }
  {  // A cyclic stream twice the cache size: LRU evicts each line before its reuse, so every access misses.
    CacheModel c(CacheConfig{32768, 64, 4});
    for (int pass = 0; pass < 3; ++pass)
      for (std::uint64_t a = 0; a < 65536; a += 64) c.access(a, 64);
    CHECK(c.stats().misses == c.stats().accesses);
  }
  {  // Conflict misses: two lines in the same set of a direct-mapped cache evict each other...
    CacheModel dm(CacheConfig{4096, 64, 1});
    for (int i = 0; i < 10; ++i) { dm.access(0, 4); dm.access(4096, 4); }
    CHECK(dm.stats().misses == 20u);
    // ...but coexist in a 2-way cache of the same size.
    CacheModel two(CacheConfig{4096, 64, 2});
    for (int i = 0; i < 10; ++i) { two.access(0, 4); two.access(2048, 4); }
    CHECK(two.stats().misses == 2u);
  }
  {  // LRU replacement order in one 2-way set: A B A C evicts B (A was used more recently).
    CacheModel c(CacheConfig{256, 64, 2});  // 2 sets; lines 0, 2, 4 map to set 0
    const std::uint64_t A = 0, B = 128, C = 256;
    c.access(A, 1); c.access(B, 1); c.access(A, 1); c.access(C, 1);
    CHECK(c.stats().misses == 3u);
    c.access(A, 1);
    CHECK(c.stats().misses == 3u);  // A still resident
    c.access(B, 1);
    CHECK(c.stats().misses == 4u);  // B was the victim
  }
  {  // A fetch straddling a line boundary touches both lines.
    CacheModel c(CacheConfig{1024, 64, 2});
    c.access(60, 8);
    CHECK(c.stats().accesses == 2u && c.stats().misses == 2u);
    c.access(0, 128);
    CHECK(c.stats().accesses == 4u && c.stats().misses == 2u);
  }
  {  // Disabled cache: every fetch goes to DRAM in 32-byte bursts.
    CacheModel c(CacheConfig{0, 64, 4});
    c.access(0, 40); c.access(0, 40);
    CHECK(c.stats().misses == 2u && c.stats().dram_bytes == 128u);
  }
  {  // reset() makes the cache cold again.
    CacheModel c(CacheConfig{1024, 64, 2});
    c.access(0, 64); c.reset(); c.access(0, 64);
    CHECK(c.stats().misses == 1u && c.stats().accesses == 1u);
  }
  {  // Bad geometry is rejected.
    bool threw = false;
    try { CacheModel c(CacheConfig{3000, 64, 4}); } catch (const std::invalid_argument&) { threw = true; }
    CHECK(threw);
    threw = false;
    try { CacheModel c(CacheConfig{128, 64, 4}); } catch (const std::invalid_argument&) { threw = true; }
    CHECK(threw);
  }
  return check_exit_code();
}
