// OpenCL runtime: device choice, program cache, kernel sources (embedded and
// from $SOFTSHELL_KERNEL_DIR), build failures with logs, cache directory.
#include <stdlib.h>
#include <unistd.h>

#include <fstream>

#include "embedded_kernels.hpp"
#include "error.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

// Sets an environment variable for the scope of a test.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old, had_ = true;
    ::setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() { had_ ? ::setenv(name_, old_.c_str(), 1) : ::unsetenv(name_); }

 private:
  const char* name_;
  std::string old_;
  bool had_ = false;
};

std::string make_temp_dir() {
  std::string tmpl = ::testing::TempDir() + "softshell-rt-XXXXXX";
  return ::mkdtemp(tmpl.data());
}

TEST(Runtime, EnumeratesAndSelectsDevices) {
  const auto devices = enumerate_devices();
  ASSERT_FALSE(devices.empty());
  for (std::size_t i = 0; i < devices.size(); ++i) {
    EXPECT_EQ(devices[i].index, int(i));
    EXPECT_FALSE(devices[i].device_name.empty());
    EXPECT_GT(devices[i].compute_units, 0u);
    EXPECT_GT(devices[i].max_alloc, 0u);
  }
  EXPECT_EQ(select_device("0").index, 0);
  const DeviceInfo& first = devices.front();
  EXPECT_EQ(select_device(first.device_name.substr(0, 6)).index, 0) << "name substring";
  const std::string type = first.type == "GPU" ? "gpu" : first.type == "CPU" ? "cpu" : "";
  if (!type.empty()) EXPECT_EQ(select_device(type).type, first.type);
}

TEST(Runtime, UnknownDeviceIsAClearError) {
  try {
    select_device("no-such-device-xyz");
    FAIL() << "expected DeviceError";
  } catch (const DeviceError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("no-such-device-xyz"), std::string::npos) << msg;
    EXPECT_NE(msg.find("found 0: "), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "one line: " << msg;
  }
  EXPECT_THROW(select_device("999"), DeviceError);
}

TEST(Runtime, EnvironmentChoosesDevice) {
  ScopedEnv env("SOFTSHELL_DEVICE", "0");
  EXPECT_EQ(select_device("").index, 0);
  ScopedEnv bad("SOFTSHELL_DEVICE", "nothing-like-this");
  EXPECT_THROW(select_device(""), DeviceError);
}

TEST(Runtime, ProgramCacheBuildsOncePerSourceAndOptions) {
  Runtime& rt = test::runtime();
  const std::size_t before = rt.programs_built();
  const cl::Program& a = rt.program("stream.cl");
  const cl::Program& b = rt.program("stream.cl");
  EXPECT_EQ(a(), b());
  const std::size_t after_first = rt.programs_built();
  EXPECT_LE(after_first - before, 1u);
  rt.program("stream.cl", "-DSOFTSHELL_TEST_OPTION=1");  // options are part of the key
  EXPECT_EQ(rt.programs_built(), after_first + 1);
  rt.program("stream.cl", "-DSOFTSHELL_TEST_OPTION=1");
  EXPECT_EQ(rt.programs_built(), after_first + 1);
}

TEST(Runtime, EmbeddedKernelsCarrySourceAndHash) {
  std::vector<std::string> names;
  for (const auto& k : embedded_kernels()) {
    names.emplace_back(k.name);
    EXPECT_FALSE(k.source.empty()) << k.name;
    EXPECT_EQ(k.hash.size(), 16u) << k.name;
  }
  for (const char* want : {"grid.h", "filter.cl", "gradient.cl", "stream.cl"})
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  // Verbatim: the embedded file equals the one in the source tree.
  std::ifstream in(std::string(SOFTSHELL_SOURCE_DIR) + "/kernels/filter.cl", std::ios::binary);
  const std::string disk((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const auto& k : embedded_kernels())
    if (k.name == "filter.cl") EXPECT_EQ(std::string(k.source), disk);
}

TEST(Runtime, IncludesExpandWithLineMarkers) {
  const std::string src = kernel_source("gradient.cl");
  EXPECT_NE(src.find("#line 1 \"grid.h\""), std::string::npos);
  EXPECT_NE(src.find("typedef struct GridDesc"), std::string::npos);
  EXPECT_NE(src.find("\"gradient.cl\""), std::string::npos);
  EXPECT_EQ(src.find("#include \"grid.h\""), std::string::npos);
}

TEST(Runtime, KernelDirOverrideAndBuildFailureCarriesLog) {
  const std::string dir = make_temp_dir();
  {
    std::ofstream f(dir + "/stream.cl");
    f << "// deliberately broken\n__kernel void stream_copy(__global float* a) {\n  a[0] = undefined_symbol;\n}\n";
  }
  ScopedEnv env("SOFTSHELL_KERNEL_DIR", dir);
  Runtime rt;
  try {
    rt.program("stream.cl");
    FAIL() << "expected KernelBuildError";
  } catch (const KernelBuildError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(rt.info().device_name), std::string::npos) << what;
    EXPECT_NE(what.find("stream.cl"), std::string::npos) << what;
    EXPECT_NE(e.log().find("undefined_symbol"), std::string::npos) << e.log();
    EXPECT_NE(e.log().find(":3:"), std::string::npos) << "line number of the error\n" << e.log();
  }
  // A kernel missing from the override directory is an error, never silently
  // replaced by the embedded copy.
  EXPECT_THROW(kernel_source("filter.cl"), InputError);
  ::unlink((dir + "/stream.cl").c_str());
  ::rmdir(dir.c_str());
}

TEST(Runtime, PoclCacheDirDefaultsToWritablePlace) {
  const std::string home = make_temp_dir();
  const char* old = std::getenv("POCL_CACHE_DIR");
  const std::string saved = old ? old : "";
  ::unsetenv("POCL_CACHE_DIR");
  ScopedEnv h("HOME", home);
  ::unsetenv("XDG_CACHE_HOME");
  const std::string dir = ensure_pocl_cache_dir();
  EXPECT_EQ(dir, home + "/.cache/softshell/pocl");
  EXPECT_EQ(::access(dir.c_str(), W_OK), 0);
  EXPECT_EQ(std::string(std::getenv("POCL_CACHE_DIR")), dir);
  // An explicit setting is respected.
  ::setenv("POCL_CACHE_DIR", "/somewhere/else", 1);
  EXPECT_EQ(ensure_pocl_cache_dir(), "/somewhere/else");
  if (old) ::setenv("POCL_CACHE_DIR", saved.c_str(), 1); else ::unsetenv("POCL_CACHE_DIR");
}


TEST(Runtime, HugePageBuffersAreOptInAlignedAndKeepTheirValues) {
  // Runtime::buffer: off by default (a huge page's first touch can cost more
  // than it saves); with set_huge_pages(true) (or SOFTSHELL_HUGE_PAGES=1) a
  // CPU device's buffers of 2 MiB and more sit on 2 MiB boundaries of host
  // memory. Either way the values go in and out unchanged, and smaller
  // buffers are the driver's.
  Runtime& rt = test::runtime();
  const char* forced = std::getenv("SOFTSHELL_HUGE_PAGES");
  if (!forced) EXPECT_FALSE(rt.huge_pages()) << "off unless asked for";
  const bool before = rt.huge_pages();
  const std::size_t n = (std::size_t(3) << 20) / sizeof(float) + 5;
  std::vector<float> values(n);
  for (std::size_t i = 0; i < n; ++i) values[i] = float(i % 8191) - 4000.0f;
  for (const bool on : {false, true}) {
    SCOPED_TRACE(on ? "huge pages" : "driver's memory");
    rt.set_huge_pages(on);
    cl::Buffer big = rt.buffer(n * sizeof(float)), little = rt.buffer(1000 * sizeof(float));
    rt.queue().enqueueWriteBuffer(big, CL_TRUE, 0, n * sizeof(float), values.data());
    EXPECT_EQ(test::download(rt, big, n), values);
    void* host = nullptr;
    clGetMemObjectInfo(big(), CL_MEM_HOST_PTR, sizeof host, &host, nullptr);
    void* small_host = nullptr;
    clGetMemObjectInfo(little(), CL_MEM_HOST_PTR, sizeof small_host, &small_host, nullptr);
    EXPECT_EQ(small_host, nullptr) << "small buffers stay the driver's";
#ifdef __linux__
    if (!forced && !rt.info().is_gpu()) {
      if (on) {
        ASSERT_NE(host, nullptr) << "a huge-page buffer wraps host memory";
        EXPECT_EQ(reinterpret_cast<std::uintptr_t>(host) % (std::size_t(2) << 20), 0u);
      } else {
        EXPECT_EQ(host, nullptr) << "without huge pages the driver allocates";
      }
    }
#endif
  }
  rt.set_huge_pages(before);
}

}  // namespace
}  // namespace softshell
