// OpenCL runtime: device discovery and choice, one context + in-order queue on
// the chosen device, and an in-memory program cache keyed by
// (device, hash(source), build options).
//
// Device choice (Runtime(request)): the request, else $SOFTSHELL_DEVICE, else
// the first GPU, else the first CPU device. A request is an index from
// `softshell devices`, a type keyword (cpu, gpu, accelerator), or a
// case-insensitive substring of "platform / device / vendor".
//
// Kernel sources come from the copies embedded at build time, or, when
// $SOFTSHELL_KERNEL_DIR is set, from that directory (for kernel development).
#pragma once

#ifndef CL_HPP_ENABLE_EXCEPTIONS
#define CL_HPP_ENABLE_EXCEPTIONS
#endif
#include <CL/opencl.hpp>

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "grid.h"

namespace softshell {

struct DeviceInfo {
  int index = -1;  // position in enumerate_devices()
  cl::Platform platform;
  cl::Device device;
  std::string platform_name, device_name, vendor, version, driver_version, opencl_c_version;
  std::string type;  // "CPU", "GPU", "ACCELERATOR", "OTHER"
  cl_uint compute_units = 0;
  cl_ulong global_mem = 0, max_alloc = 0, local_mem = 0;
  std::size_t max_work_group = 0;
  cl_uint mem_base_addr_align_bits = 0;
  bool is_gpu() const { return type == "GPU"; }
  std::string label() const;  // "pthread-haswell (CPU, Portable Computing Language)"
};

// Every device on every platform, in a stable order (platform, then device).
// Throws DeviceError when no platform is installed.
std::vector<DeviceInfo> enumerate_devices();

// Resolves a request (see above) against enumerate_devices(). An empty request
// means $SOFTSHELL_DEVICE, then the default rule. Throws DeviceError.
DeviceInfo select_device(const std::string& request = "");

// Sets POCL_CACHE_DIR to a writable directory of ours when the user has not
// set it, so PoCL's on-disk kernel cache makes a second run skip compilation.
// Called before the first platform query. Returns the directory in force.
std::string ensure_pocl_cache_dir();

// The source of kernels/<file> with `#include "x.h"` lines of embedded headers
// expanded in place (with #line markers so build-log line numbers stay true).
std::string kernel_source(const std::string& file);

class Runtime {
 public:
  explicit Runtime(const std::string& request = "");

  const DeviceInfo& info() const { return info_; }
  const cl::Context& context() const { return context_; }
  const cl::Device& device() const { return info_.device; }
  cl::CommandQueue& queue() { return queue_; }

  // Built program for kernels/<file> with `options`; built once per runtime.
  // A failed build throws KernelBuildError with the device name and full log.
  const cl::Program& program(const std::string& file, const std::string& options = "");
  cl::Kernel kernel(const std::string& file, const std::string& name, const std::string& options = "");

  // Device buffer of `bytes`, checked against the device's limits (throws
  // DeviceError naming the need and the limit instead of failing obscurely).
  cl::Buffer buffer(std::size_t bytes, cl_mem_flags flags = CL_MEM_READ_WRITE);
  void check_allocation(std::size_t bytes, const std::string& what) const;

  // Sets a kernel's arguments in order: set_args(k, in, out, grid).
  template <class... Args>
  static void set_args(cl::Kernel& k, const Args&... args) {
    cl_uint i = 0;
    (k.setArg(i++, args), ...);
  }
  // Enqueues a voxel kernel over the grid (3-D, x fastest) or a 1-D kernel
  // over n items; global sizes are rounded up, kernels bounds-check.
  cl::Event enqueue_3d(const cl::Kernel& k, const GridDesc& g, const std::vector<cl::Event>* wait = nullptr);
  cl::Event enqueue_1d(const cl::Kernel& k, std::size_t n, const std::vector<cl::Event>* wait = nullptr);
  // Enqueues a row kernel: one work-item (and work-group) per x-row of the
  // grid, global size ny x nz; the kernel walks its row itself (the CPU
  // layouts of kernels/multigrid.cl).
  cl::Event enqueue_rows(const cl::Kernel& k, const GridDesc& g);

  // Work-group shape for 3-D voxel kernels and a global size rounded up to it.
  cl::NDRange local_3d() const;
  cl::NDRange global_3d(const GridDesc& g) const;
  cl::NDRange local_1d() const;
  cl::NDRange global_1d(std::size_t n) const;

  std::size_t programs_built() const { return builds_; }

  // CPU device buffers of 2 MiB and more in transparent huge pages (fewer TLB
  // misses for the solver's kernels, which walk a dozen arrays at once). Off
  // by default: on a VM whose freed 2 MiB blocks go back to the hypervisor
  // (free page reporting) a huge page's first touch faults on the host, and
  // a one-shot 256^3 classification took 1.0-1.3 s longer in its setup, while
  // the viewer's re-solve measured the same with and without.
  // SOFTSHELL_HUGE_PAGES=0 or 1 overrides this (docs/benchmarks.md, "Huge
  // pages: first touch on a VM").
  void set_huge_pages(bool on) { huge_pages_ = on; }
  bool huge_pages() const;

 private:
  DeviceInfo info_;
  cl::Context context_;
  cl::CommandQueue queue_;
  std::map<std::string, cl::Program> programs_;
  std::size_t builds_ = 0;
  bool huge_pages_ = false;
};

// Seconds between an event's start and end (queue has profiling enabled).
double event_seconds(const cl::Event& e);
// Seconds from the start of `first` to the end of `last`.
double event_span_seconds(const cl::Event& first, const cl::Event& last);

// Readable name of an OpenCL error code, e.g. "CL_OUT_OF_RESOURCES".
const char* cl_error_name(cl_int code);

}  // namespace softshell
