// OpenCL runtime: device discovery/choice, context and queue, program cache,
// kernel sources (embedded or from $SOFTSHELL_KERNEL_DIR).
#include "cl_runtime.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "embedded_kernels.hpp"
#include "error.hpp"
#include "huge_pages.hpp"
#include "text.hpp"

namespace softshell {
namespace {

std::string type_name(cl_device_type t) {
  if (t & CL_DEVICE_TYPE_GPU) return "GPU";
  if (t & CL_DEVICE_TYPE_CPU) return "CPU";
  if (t & CL_DEVICE_TYPE_ACCELERATOR) return "ACCELERATOR";
  return "OTHER";
}

const char* k_install_hint =
    "install an OpenCL driver, e.g. PoCL for the CPU: apt-get install pocl-opencl-icd";

bool make_dirs(const std::string& path) {
  std::string partial;
  std::stringstream ss(path);
  std::string part;
  if (!path.empty() && path[0] == '/') partial = "/";
  while (std::getline(ss, part, '/')) {
    if (part.empty()) continue;
    partial += part + "/";
    if (::mkdir(partial.c_str(), 0755) != 0 && errno != EEXIST) return false;
  }
  return ::access(path.c_str(), W_OK) == 0;
}

// 64-bit FNV-1a: a cheap, stable hash for the program-cache key.
std::uint64_t fnv1a(const std::string& s) {
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

std::string raw_source(const std::string& file) {
  if (const char* dir = std::getenv("SOFTSHELL_KERNEL_DIR"); dir && *dir) {
    const std::string path = std::string(dir) + "/" + file;
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError("SOFTSHELL_KERNEL_DIR: cannot read kernel source " + path);
    std::ostringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }
  for (const auto& k : embedded_kernels())
    if (k.name == file) return std::string(k.source);
  // A missing kernel is a build-system bug, never silently ignored.
  throw std::logic_error("kernel source '" + file + "' is not embedded in this build");
}

}  // namespace

std::string DeviceInfo::label() const {
  return device_name + " (" + type + ", " + platform_name + ")";
}

std::string ensure_pocl_cache_dir() {
  if (const char* set = std::getenv("POCL_CACHE_DIR"); set && *set) return set;
  std::vector<std::string> candidates;
  if (const char* xdg = std::getenv("XDG_CACHE_HOME"); xdg && *xdg)
    candidates.push_back(std::string(xdg) + "/softshell/pocl");
  if (const char* home = std::getenv("HOME"); home && *home)
    candidates.push_back(std::string(home) + "/.cache/softshell/pocl");
  candidates.push_back("/tmp/softshell-pocl-" + std::to_string(::getuid()));
  for (const auto& dir : candidates) {
    if (make_dirs(dir)) {
      ::setenv("POCL_CACHE_DIR", dir.c_str(), 0);
      return dir;
    }
  }
  return "";  // PoCL then falls back to its own default or no disk cache
}

std::vector<DeviceInfo> enumerate_devices() {
  ensure_pocl_cache_dir();
  std::vector<cl::Platform> platforms;
  try {
    cl::Platform::get(&platforms);
  } catch (const cl::Error& e) {
    // ocl-icd reports "no platform" as CL_PLATFORM_NOT_FOUND_KHR (-1001).
    platforms.clear();
  }
  if (platforms.empty())
    throw DeviceError(std::string("no OpenCL platform found (no driver registered in /etc/OpenCL/vendors); ") +
                      k_install_hint);
  std::vector<DeviceInfo> out;
  for (auto& p : platforms) {
    std::vector<cl::Device> devices;
    try {
      p.getDevices(CL_DEVICE_TYPE_ALL, &devices);
    } catch (const cl::Error&) {
      continue;  // a platform with no devices (CL_DEVICE_NOT_FOUND) is skipped
    }
    for (auto& d : devices) {
      DeviceInfo info;
      info.index = static_cast<int>(out.size());
      info.platform = p;
      info.device = d;
      info.platform_name = trim(p.getInfo<CL_PLATFORM_NAME>());
      info.device_name = trim(d.getInfo<CL_DEVICE_NAME>());
      info.vendor = trim(d.getInfo<CL_DEVICE_VENDOR>());
      info.version = trim(d.getInfo<CL_DEVICE_VERSION>());
      info.driver_version = trim(d.getInfo<CL_DRIVER_VERSION>());
      info.opencl_c_version = trim(d.getInfo<CL_DEVICE_OPENCL_C_VERSION>());
      info.type = type_name(d.getInfo<CL_DEVICE_TYPE>());
      info.compute_units = d.getInfo<CL_DEVICE_MAX_COMPUTE_UNITS>();
      info.global_mem = d.getInfo<CL_DEVICE_GLOBAL_MEM_SIZE>();
      info.max_alloc = d.getInfo<CL_DEVICE_MAX_MEM_ALLOC_SIZE>();
      info.local_mem = d.getInfo<CL_DEVICE_LOCAL_MEM_SIZE>();
      info.max_work_group = d.getInfo<CL_DEVICE_MAX_WORK_GROUP_SIZE>();
      info.mem_base_addr_align_bits = d.getInfo<CL_DEVICE_MEM_BASE_ADDR_ALIGN>();
      out.push_back(std::move(info));
    }
  }
  if (out.empty())
    throw DeviceError("OpenCL platforms found (" + std::to_string(platforms.size()) +
                      ") but none has a device; " + k_install_hint);
  return out;
}

DeviceInfo select_device(const std::string& request_in) {
  std::string request = trim(request_in);
  std::string source = "--device";
  if (request.empty()) {
    if (const char* env = std::getenv("SOFTSHELL_DEVICE"); env && *env) {
      request = trim(env);
      source = "SOFTSHELL_DEVICE";
    }
  }
  const auto devices = enumerate_devices();
  auto found_list = [&] {
    std::string s;
    for (const auto& d : devices) s += (s.empty() ? "" : "; ") + std::to_string(d.index) + ": " + d.label();
    return s;
  };
  if (request.empty()) {
    for (const auto& d : devices)
      if (d.is_gpu()) return d;
    for (const auto& d : devices)
      if (d.type == "CPU") return d;
    return devices.front();
  }
  if (std::all_of(request.begin(), request.end(), [](unsigned char c) { return std::isdigit(c); })) {
    const long idx = std::strtol(request.c_str(), nullptr, 10);
    if (request.size() < 6 && idx >= 0 && idx < static_cast<long>(devices.size())) return devices[idx];
    throw DeviceError(source + " " + request + ": no device with that index; found " + found_list());
  }
  const std::string want = lower(request);
  for (const char* kw : {"cpu", "gpu", "accelerator"}) {
    if (want == kw) {
      for (const auto& d : devices)
        if (lower(d.type) == want) return d;
      throw DeviceError(source + " " + request + ": no " + want + " device; found " + found_list() +
                        (want == "cpu" ? std::string("; ") + k_install_hint : std::string()));
    }
  }
  for (const auto& d : devices) {
    const std::string hay = lower(d.platform_name + " / " + d.device_name + " / " + d.vendor);
    if (hay.find(want) != std::string::npos) return d;
  }
  throw DeviceError(source + " '" + request + "': no device name matches; found " + found_list());
}

std::string kernel_source(const std::string& file) {
  const std::string src = raw_source(file);
  std::istringstream in(src);
  std::ostringstream out;
  std::string line;
  int lineno = 0;
  while (std::getline(in, line)) {
    ++lineno;
    const auto pos = line.find("#include \"");
    if (pos != std::string::npos && line.find_first_not_of(" \t") == pos) {
      const auto start = pos + 10;
      const auto end = line.find('"', start);
      const std::string inc = line.substr(start, end - start);
      out << "#line 1 \"" << inc << "\"\n" << kernel_source(inc) << "\n#line " << (lineno + 1) << " \"" << file
          << "\"\n";
      continue;
    }
    out << line << '\n';
  }
  return out.str();
}

Runtime::Runtime(const std::string& request) : info_(select_device(request)) {
  context_ = cl::Context(info_.device);
  queue_ = cl::CommandQueue(context_, info_.device, CL_QUEUE_PROFILING_ENABLE);
}

const cl::Program& Runtime::program(const std::string& file, const std::string& options) {
  // Embedded sources never change: the key is the file and the options, and
  // a hit costs no source assembly. Sources read from SOFTSHELL_KERNEL_DIR
  // may be edited while the process runs: their hash is part of the key.
  const char* dir = std::getenv("SOFTSHELL_KERNEL_DIR");
  const bool from_disk = dir && *dir;
  std::string src;
  std::ostringstream key;
  key << file << '|' << options;
  if (from_disk) {
    src = kernel_source(file);
    key << '|' << std::hex << fnv1a(src);
  }
  if (auto it = programs_.find(key.str()); it != programs_.end()) return it->second;
  if (!from_disk) src = kernel_source(file);

  cl::Program prog(context_, src);
  const std::string opts = "-cl-std=CL1.2 " + options;
  try {
    prog.build({info_.device}, opts.c_str());
  } catch (const cl::Error& e) {
    std::string log;
    try {
      log = prog.getBuildInfo<CL_PROGRAM_BUILD_LOG>(info_.device);
    } catch (const cl::Error&) {
      log = "(no build log available)";
    }
    throw KernelBuildError("OpenCL build of kernels/" + file + " failed on " + info_.device_name + " (" +
                               cl_error_name(e.err()) + ", options '" + opts + "')",
                           log);
  }
  ++builds_;
  return programs_.emplace(key.str(), std::move(prog)).first->second;
}

cl::Kernel Runtime::kernel(const std::string& file, const std::string& name, const std::string& options) {
  const cl::Program& prog = program(file, options);
  try {
    return cl::Kernel(prog, name.c_str());
  } catch (const cl::Error&) {
    throw std::logic_error("kernel '" + name + "' not found in kernels/" + file);
  }
}

void Runtime::check_allocation(std::size_t bytes, const std::string& what) const {
  auto mib = [](double b) { return std::to_string(static_cast<long long>(b / (1024.0 * 1024.0))) + " MiB"; };
  if (bytes > info_.max_alloc)
    throw DeviceError(what + " needs a " + mib(bytes) + " buffer, but " + info_.device_name +
                      " allows at most " + mib(info_.max_alloc) + " per allocation; choose another --device or a smaller volume");
  if (bytes > info_.global_mem)
    throw DeviceError(what + " needs " + mib(bytes) + ", more than the " + mib(info_.global_mem) +
                      " of " + info_.device_name);
}

namespace {

// Host memory for a CPU device's buffers in 2 MiB pages (docs/benchmarks.md,
// "Huge pages"): the solver's kernels walk up to 40 arrays at once, and with
// 4 KiB pages every one of them misses the TLB every 1024 floats; a fresh
// buffer's first touch also faults 512x less often. Transparent huge pages
// are "madvise" on Debian, and PoCL's own allocations are not advised, so
// softshell allocates, advises and hands the memory to PoCL
// (CL_MEM_USE_HOST_PTR, which the CPU device uses in place); the buffer's
// destructor callback frees it.
void CL_CALLBACK free_host_memory(cl_mem, void* p) { std::free(p); }

cl::Buffer huge_page_buffer(const cl::Context& context, cl_mem_flags flags, std::size_t bytes) {
  void* p = huge_page_alloc(bytes);
  if (!p) return cl::Buffer();
  cl_int err = CL_SUCCESS;
  cl_mem m = clCreateBuffer(context(), flags | CL_MEM_USE_HOST_PTR, bytes, p, &err);
  if (err != CL_SUCCESS || !m) {
    std::free(p);
    return cl::Buffer();
  }
  if (clSetMemObjectDestructorCallback(m, free_host_memory, p) != CL_SUCCESS) {
    // Without the callback the memory could not be given back: keep it
    // only as long as the buffer by not using this path.
    clReleaseMemObject(m);
    std::free(p);
    return cl::Buffer();
  }
  return cl::Buffer(m);  // takes the reference clCreateBuffer gave
}

}  // namespace

bool Runtime::huge_pages() const {
  // SOFTSHELL_HUGE_PAGES=0 or 1 overrides set_huge_pages().
  static const int forced = [] {
    const char* e = std::getenv("SOFTSHELL_HUGE_PAGES");
    if (!e) return -1;
    const std::string s(e);
    return s == "0" ? 0 : s == "1" ? 1 : -1;
  }();
  return forced >= 0 ? forced == 1 : huge_pages_;
}

cl::Buffer Runtime::buffer(std::size_t bytes, cl_mem_flags flags) {
  check_allocation(bytes, "a volume");
  const bool host_flags = flags & (CL_MEM_USE_HOST_PTR | CL_MEM_ALLOC_HOST_PTR | CL_MEM_COPY_HOST_PTR);
  if (huge_pages() && !info_.is_gpu() && bytes >= kHugePageBytes && !host_flags) {
    cl::Buffer b = huge_page_buffer(context_, flags, bytes);
    if (b() != nullptr) return b;
  }
  return cl::Buffer(context_, flags, std::max<std::size_t>(bytes, 4));
}

cl::NDRange Runtime::local_3d() const {
  // 64 consecutive x voxels per group: vector-friendly on CPUs, coalesced on GPUs.
  if (info_.max_work_group >= 256 && info_.is_gpu()) return cl::NDRange(64, 4, 1);
  if (info_.max_work_group >= 64) return cl::NDRange(64, 1, 1);
  return cl::NDRange(info_.max_work_group, 1, 1);
}

cl::NDRange Runtime::global_3d(const GridDesc& g) const {
  const cl::NDRange l = local_3d();
  auto up = [](std::size_t n, std::size_t m) { return (n + m - 1) / m * m; };
  return cl::NDRange(up(g.nx, l[0]), up(g.ny, l[1]), up(g.nz, l[2]));
}

cl::NDRange Runtime::local_1d() const { return cl::NDRange(std::min<std::size_t>(256, info_.max_work_group)); }

cl::NDRange Runtime::global_1d(std::size_t n) const {
  const std::size_t l = local_1d()[0];
  return cl::NDRange((n + l - 1) / l * l);
}

cl::Event Runtime::enqueue_3d(const cl::Kernel& k, const GridDesc& g, const std::vector<cl::Event>* wait) {
  cl::Event e;
  queue_.enqueueNDRangeKernel(k, cl::NullRange, global_3d(g), local_3d(), wait, &e);
  return e;
}

cl::Event Runtime::enqueue_1d(const cl::Kernel& k, std::size_t n, const std::vector<cl::Event>* wait) {
  cl::Event e;
  queue_.enqueueNDRangeKernel(k, cl::NullRange, global_1d(n), local_1d(), wait, &e);
  return e;
}

cl::Event Runtime::enqueue_rows(const cl::Kernel& k, const GridDesc& g) {
  cl::Event e;
  queue_.enqueueNDRangeKernel(k, cl::NullRange, cl::NDRange(std::size_t(g.ny), std::size_t(g.nz)),
                              cl::NDRange(1, 1), nullptr, &e);
  return e;
}

double event_seconds(const cl::Event& e) {
  const auto start = e.getProfilingInfo<CL_PROFILING_COMMAND_START>();
  const auto end = e.getProfilingInfo<CL_PROFILING_COMMAND_END>();
  return static_cast<double>(end - start) * 1e-9;
}

double event_span_seconds(const cl::Event& first, const cl::Event& last) {
  const auto start = first.getProfilingInfo<CL_PROFILING_COMMAND_START>();
  const auto end = last.getProfilingInfo<CL_PROFILING_COMMAND_END>();
  return static_cast<double>(end - start) * 1e-9;
}

const char* cl_error_name(cl_int code) {
  switch (code) {
#define CASE(x) \
  case x:       \
    return #x;
    CASE(CL_SUCCESS) CASE(CL_DEVICE_NOT_FOUND) CASE(CL_DEVICE_NOT_AVAILABLE) CASE(CL_COMPILER_NOT_AVAILABLE)
    CASE(CL_MEM_OBJECT_ALLOCATION_FAILURE) CASE(CL_OUT_OF_RESOURCES) CASE(CL_OUT_OF_HOST_MEMORY)
    CASE(CL_PROFILING_INFO_NOT_AVAILABLE) CASE(CL_MEM_COPY_OVERLAP) CASE(CL_BUILD_PROGRAM_FAILURE)
    CASE(CL_MAP_FAILURE) CASE(CL_MISALIGNED_SUB_BUFFER_OFFSET) CASE(CL_INVALID_VALUE)
    CASE(CL_INVALID_DEVICE_TYPE) CASE(CL_INVALID_PLATFORM) CASE(CL_INVALID_DEVICE) CASE(CL_INVALID_CONTEXT)
    CASE(CL_INVALID_QUEUE_PROPERTIES) CASE(CL_INVALID_COMMAND_QUEUE) CASE(CL_INVALID_HOST_PTR)
    CASE(CL_INVALID_MEM_OBJECT) CASE(CL_INVALID_BUFFER_SIZE) CASE(CL_INVALID_BINARY)
    CASE(CL_INVALID_BUILD_OPTIONS) CASE(CL_INVALID_PROGRAM) CASE(CL_INVALID_PROGRAM_EXECUTABLE)
    CASE(CL_INVALID_KERNEL_NAME) CASE(CL_INVALID_KERNEL_DEFINITION) CASE(CL_INVALID_KERNEL)
    CASE(CL_INVALID_ARG_INDEX) CASE(CL_INVALID_ARG_VALUE) CASE(CL_INVALID_ARG_SIZE)
    CASE(CL_INVALID_KERNEL_ARGS) CASE(CL_INVALID_WORK_DIMENSION) CASE(CL_INVALID_WORK_GROUP_SIZE)
    CASE(CL_INVALID_WORK_ITEM_SIZE) CASE(CL_INVALID_GLOBAL_OFFSET) CASE(CL_INVALID_EVENT_WAIT_LIST)
    CASE(CL_INVALID_EVENT) CASE(CL_INVALID_OPERATION) CASE(CL_INVALID_GLOBAL_WORK_SIZE)
#undef CASE
    case -1001:
      return "CL_PLATFORM_NOT_FOUND_KHR";
    default:
      return "unknown OpenCL error";
  }
}

}  // namespace softshell
