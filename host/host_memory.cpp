#include "host_memory.hpp"

#include <climits>
#include <mutex>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

namespace softshell {
namespace {
std::mutex g_lock;
int g_depth = 0;  // scopes alive; nested ones change nothing
}  // namespace

KeepFreedMemory::KeepFreedMemory() {
  std::lock_guard<std::mutex> hold(g_lock);
  if (g_depth++ > 0) return;
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);                // every block from the heap, none mapped on its own
  mallopt(M_TRIM_THRESHOLD, INT_MAX);    // and the heap's free top kept
#endif
}

KeepFreedMemory::~KeepFreedMemory() {
  std::lock_guard<std::mutex> hold(g_lock);
  if (--g_depth > 0) return;
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 65536);            // glibc's defaults (DEFAULT_MMAP_MAX, DEFAULT_TRIM_THRESHOLD)
  mallopt(M_TRIM_THRESHOLD, 128 * 1024);
  malloc_trim(0);                        // the free pages back to the kernel
#endif
}

}  // namespace softshell
