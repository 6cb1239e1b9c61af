#pragma once
// Counts every allocation of the test executable while armed: the replaced global operator new
// and, with btAlignedAllocSetCustom(countingAlloc, std::free), Bullet's aligned allocator.
// Include from one translation unit per executable (it defines the replacement operators).
#include <atomic>
#include <cstdlib>
#include <new>

namespace fibremss::testing {

inline std::atomic<bool> countingArmed{false};  ///< count allocations now
inline std::atomic<long> allocationCount{0};    ///< allocations counted while armed

/// Bullet's allocation hook: counts, then mallocs.
inline void* countingAlloc(size_t size) {
  allocationCount += countingArmed ? 1 : 0;
  return std::malloc(size);
}

/// Frees what the replaced operator new allocated; not inlined, so the compiler cannot pair the
/// replaced new with free() and warn.
[[gnu::noinline]] inline void releaseBlock(void* block) noexcept {
  std::free(block);
}

}  // namespace fibremss::testing

void* operator new(size_t size) {
  fibremss::testing::allocationCount += fibremss::testing::countingArmed ? 1 : 0;
  void* block = std::malloc(size == 0 ? 1 : size);
  if (!block) throw std::bad_alloc();
  return block;
}
// The nothrow form too (std::stable_sort's temporary buffer uses it): its memory comes back
// through the replaced delete, so a sanitizer's own nothrow new would mismatch with free().
void* operator new(size_t size, const std::nothrow_t&) noexcept {
  fibremss::testing::allocationCount += fibremss::testing::countingArmed ? 1 : 0;
  return std::malloc(size == 0 ? 1 : size);
}
void operator delete(void* block, const std::nothrow_t&) noexcept {
  fibremss::testing::releaseBlock(block);
}
void operator delete(void* block) noexcept {
  fibremss::testing::releaseBlock(block);
}
void operator delete(void* block, size_t) noexcept {
  fibremss::testing::releaseBlock(block);
}
