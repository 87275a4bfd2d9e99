// Test entry point and shared fixtures (see test_support.hpp).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <memory>

#include "test_support.hpp"

namespace softshell::test {

Runtime& runtime() {
  static std::unique_ptr<Runtime> rt;
  if (!rt) {
    rt = std::make_unique<Runtime>();
    std::cout << "[ device   ] " << rt->info().label() << "  (SOFTSHELL_DEVICE="
              << (std::getenv("SOFTSHELL_DEVICE") ? std::getenv("SOFTSHELL_DEVICE") : "") << ")\n";
  }
  return *rt;
}

std::uint64_t seed() {
  static std::uint64_t s = [] {
    const char* env = std::getenv("SOFTSHELL_TEST_SEED");
    const std::uint64_t v = env && *env ? std::strtoull(env, nullptr, 10) : 20261121ull;
    std::cout << "[ seed     ] " << v << "  (set SOFTSHELL_TEST_SEED to change)\n";
    return v;
  }();
  return s;
}

std::string shared_data_dir() {
  const char* env = std::getenv("SOFTSHELL_SHARED_DATA");
  if (env && *env) return env;
  // The volumes shipped in the source tree (data/README.md) first, then
  // ../shared/data beside it.
  const std::string shipped = std::string(SOFTSHELL_SOURCE_DIR) + "/data";
  if (std::filesystem::exists(shipped + "/plus-spine")) return shipped;
  return SOFTSHELL_SHARED_DATA;
}

bool in_ci() {
  const char* ci = std::getenv("CI");
  return ci && std::string(ci) == "true";
}

Volume shell_volume(int n) {
  Volume u({std::size_t(n), std::size_t(n), std::size_t(n)}, {0.8, 0.8, 0.8});
  const double c = 0.5 * (n - 1), r = 0.3 * n;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const double d = std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c));
        u.at(x, y, z) = float(std::max(0.0, 1.0 - std::abs(d - r) / 1.5));
      }
  return u;
}

Volume random_volume(Dims3 dims, Vec3d spacing, std::uint64_t s, float lo, float hi) {
  Volume v(dims, spacing, ScalarType::Float32);
  std::mt19937_64 rng(s);
  for (float& f : v.data) f = lo + (hi - lo) * static_cast<float>((rng() >> 40) * (1.0 / 16777216.0));
  return v;
}

cl::Buffer upload(Runtime& rt, const std::vector<float>& host) {
  cl::Buffer b = rt.buffer(host.size() * sizeof(float));
  rt.queue().enqueueWriteBuffer(b, CL_TRUE, 0, host.size() * sizeof(float), host.data());
  return b;
}

std::vector<float> download(Runtime& rt, const cl::Buffer& buf, std::size_t n) {
  std::vector<float> out(n);
  rt.queue().enqueueReadBuffer(buf, CL_TRUE, 0, n * sizeof(float), out.data());
  return out;
}

::testing::AssertionResult all_near(const std::vector<float>& got, const std::vector<double>& want, Dims3 dims,
                                    double abs_tol, double rel_tol) {
  if (got.size() != want.size())
    return ::testing::AssertionFailure() << "size " << got.size() << " != " << want.size();
  std::size_t bad = 0, first = got.size();
  double worst = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double err = std::abs(double(got[i]) - want[i]);
    if (!(err <= abs_tol + rel_tol * std::abs(want[i]))) {
      if (first == got.size()) first = i;
      ++bad;
    }
    if (!(err <= worst)) worst = err;
  }
  if (bad == 0) return ::testing::AssertionSuccess();
  const std::size_t x = first % dims[0], y = (first / dims[0]) % dims[1], z = first / (dims[0] * dims[1]);
  return ::testing::AssertionFailure() << bad << " of " << got.size() << " samples differ; first at (" << x << ", "
                                       << y << ", " << z << "): got " << got[first] << ", want " << want[first]
                                       << "; worst abs error " << worst;
}

double max_relative_deviation(const std::vector<float>& a, const std::vector<float>& b) {
  double dev = 0, scale = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i)
    dev = std::max(dev, double(std::abs(a[i] - b[i]))), scale = std::max(scale, double(std::abs(b[i])));
  return scale > 0 ? dev / scale : dev;
}

double relative_l2(const std::vector<float>& a, const std::vector<float>& b) {
  double num = 0, den = 0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    const double e = double(a[i]) - double(b[i]);
    num += e * e, den += double(b[i]) * double(b[i]);
  }
  return den > 0 ? std::sqrt(num / den) : std::sqrt(num);
}

MeanDeviation mean_deviation(const std::vector<float>& a, const std::vector<float>& b, double beyond) {
  MeanDeviation d;
  const std::size_t n = std::min(a.size(), b.size());
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double e = std::abs(double(a[i]) - double(b[i]));
    d.mean += e, count += e > beyond;
  }
  if (n > 0) d.mean /= double(n), d.share = double(count) / double(n);
  return d;
}

}  // namespace softshell::test

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
