// Freed blocks kept for reuse through the host stages of a classification.
//
// The host stages (mask, near field, fill, automatic isovalue) each allocate
// and free arrays of 1 to 4 bytes per voxel. The C library hands blocks of
// 32 MiB and more (64 MiB: a 256^3 float array) to the kernel when they are
// freed and maps fresh pages for the next one, and on this kind of VM each
// fresh page's first touch costs a fault: about 2 ms per 4 MiB, 0.03 s per
// 256^3 float array and thread (docs/benchmarks.md, "Host stages", fifth
// round). While a KeepFreedMemory lives, freed blocks stay in the process and
// the next allocation reuses their pages; when the last one ends, the C
// library's defaults return and the free pages are given back (malloc_trim).
// End it before device work: OpenCL's allocations made inside the scope
// spread over the kept heap, and the peak of the solve after them rose by
// 40-95 MB at 256^3 when the shadow walls' kernels ran inside it.
#pragma once

namespace softshell {

class KeepFreedMemory {
 public:
  KeepFreedMemory();
  ~KeepFreedMemory();
  KeepFreedMemory(const KeepFreedMemory&) = delete;
  KeepFreedMemory& operator=(const KeepFreedMemory&) = delete;
};

}  // namespace softshell
