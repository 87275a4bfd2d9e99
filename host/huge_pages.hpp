// Host memory in transparent huge pages (2 MiB): one fault per 2 MiB of first
// touch instead of per 4 KiB, and fewer TLB misses for kernels that walk many
// arrays at once. Debian's transparent huge pages are in `madvise` mode, so a
// block gets them only when it is 2 MiB-aligned and advised.
#pragma once

#include <cstddef>
#include <cstdlib>

#ifdef __linux__
#include <sys/mman.h>
#endif

namespace softshell {

constexpr std::size_t kHugePageBytes = std::size_t(2) << 20;

// At least `bytes` (rounded up to a whole number of huge pages), 2 MiB-aligned
// and advised for huge pages; nullptr when the allocation fails. Free it with
// std::free. The advice is only advice: where it fails or transparent huge
// pages are off, the pages stay 4 KiB and nothing else changes.
inline void* huge_page_alloc(std::size_t bytes) {
  if (bytes > std::size_t(-1) - kHugePageBytes) return nullptr;
  const std::size_t rounded = (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
  void* p = std::aligned_alloc(kHugePageBytes, rounded);
#ifdef __linux__
  if (p) madvise(p, rounded, MADV_HUGEPAGE);
#endif
  return p;
}

}  // namespace softshell
