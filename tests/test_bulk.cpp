// The isovalue above the bulk (host/auto_iso.hpp, AutoIsoParams::bulk_spread;
// docs/parameters.md, "The isovalue above the bulk"): the bulk's mode and
// half-width on data whose histogram is known in closed form (a profile
// whose values follow a Gaussian, the inverse of its distribution function),
// only the scanned voxels counted, the same bits for any thread count, the
// rule's cases, and classify's report and switch on a family spine and face.
#include <cmath>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

#include "auto_iso.hpp"
#include "io.hpp"
#include "cli_fixture.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

// The standard normal quantile by bisection of 0.5 erfc(-x / sqrt 2).
double normal_quantile(double p) {
  double lo = -10, hi = 10;
  for (int k = 0; k < 200; ++k) {
    const double mid = 0.5 * (lo + hi);
    (0.5 * std::erfc(-mid / std::sqrt(2.0)) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

// A volume nx x 4 x 4 whose value along x runs through the quantiles of a
// Gaussian (mean m, sd s) -- its histogram is that Gaussian -- and, for the
// last `echo_share` of x, through those of a narrower one 8 s higher: a
// bright minority that must not move the bulk.
Volume gaussian_profile(std::size_t nx, double m, double s, double echo_share) {
  Volume v({nx, 4, 4}, {0.1, 0.1, 0.1});
  const std::size_t bulk = std::size_t(double(nx) * (1.0 - echo_share));
  for (std::size_t x = 0; x < nx; ++x) {
    const bool echo = x >= bulk;
    const std::size_t k = echo ? x - bulk : x, n = echo ? nx - bulk : bulk;
    const double value = echo ? m + 8 * s + 0.3 * s * normal_quantile((double(k) + 0.5) / double(n))
                              : m + s * normal_quantile((double(k) + 0.5) / double(n));
    for (std::size_t z = 0; z < 4; ++z)
      for (std::size_t y = 0; y < 4; ++y) v.at(x, y, z) = float(value);
  }
  return v;
}

TEST(Bulk, AGaussianHistogramGivesItsModeAndHalfWidth) {
  // The lowpass (0.05 mm, half a voxel) hardly bends the smooth profile; the
  // bins are 1/128 of +-2.58 sd (the 0.5th to 99.5th percentiles).
  const double m = 120, s = 10;
  const Bulk b = bulk_of(gaussian_profile(6000, m, s, 0.0), nullptr, 0.05);
  ASSERT_TRUE(b.measured);
  const double bin = 2 * 2.576 * s / 128;
  EXPECT_NEAR(b.mode, m, 2 * bin);
  EXPECT_NEAR(b.half_width, std::sqrt(2 * std::log(2.0)) * s, 0.08 * s) << "HWHM 1.177 sd";
  // A bright tenth (echoes) leaves the bulk where it was.
  const Bulk e = bulk_of(gaussian_profile(6000, m, s, 0.1), nullptr, 0.05);
  ASSERT_TRUE(e.measured);
  EXPECT_NEAR(e.mode, m, 0.3 * s);
  EXPECT_NEAR(e.half_width, std::sqrt(2 * std::log(2.0)) * s, 0.15 * s);
}

TEST(Bulk, OnlyScannedVoxelsCountAndTheThreadCountDoesNotMatter) {
  const Volume v = gaussian_profile(3000, 80, 6, 0.05);
  // The same profile with a third more voxels, bright and unscanned.
  Volume w({4000, 4, 4}, v.spacing);
  std::vector<std::uint8_t> mask(w.voxels(), 0);
  for (std::size_t z = 0; z < 4; ++z)
    for (std::size_t y = 0; y < 4; ++y)
      for (std::size_t x = 0; x < 4000; ++x) {
        const bool in = x < 3000;
        w.at(x, y, z) = in ? v.at(x, y, z) : 250.0f;
        mask[w.index(x, y, z)] = in;
      }
  const Bulk a = bulk_of(v, nullptr, 0.05), b = bulk_of(w, &mask, 0.05);
  ASSERT_TRUE(a.measured && b.measured);
  // The unscanned voxels' blur reaches a voxel or two into the scanned ones.
  EXPECT_NEAR(b.mode, a.mode, 0.5);
  EXPECT_NEAR(b.half_width, a.half_width, 0.5);
  for (int threads : {1, 2, 3}) {
    const Bulk t = bulk_of(w, &mask, 0.05, threads);
    EXPECT_EQ(t.mode, b.mode) << threads;
    EXPECT_EQ(t.half_width, b.half_width) << threads;
  }
}

TEST(Bulk, RefusesBadArgumentsAndReportsTooLittleData) {
  const Volume v = gaussian_profile(300, 80, 6, 0.0);
  const std::vector<std::uint8_t> wrong(10, 1);
  EXPECT_THROW(bulk_of(v, &wrong, 1.0), std::invalid_argument);
  EXPECT_THROW(bulk_of(v, nullptr, 0.0), std::invalid_argument);
  std::vector<std::uint8_t> few(v.voxels(), 0);
  for (std::size_t i = 0; i < 999; ++i) few[i] = 1;
  EXPECT_FALSE(bulk_of(v, &few, 1.0).measured) << "under 1000 scanned voxels";
  Volume flat({20, 20, 20}, {1, 1, 1});
  for (float& x : flat.data) x = 7.0f;
  EXPECT_FALSE(bulk_of(flat, nullptr, 1.0).measured) << "no range";
}

TEST(Bulk, TheIsovalueIsRaisedOnlyFromTheBulksUpperTailUnderTheCrests) {
  Bulk b;
  b.measured = true, b.mode = 100, b.half_width = 10;  // reach 115 at spread 1.5
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 140, b, 1.5, 0.8, 0.6), 115) << "in the tail, crests well above";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(95, 140, b, 1.5, 0.8, 0.6), 95) << "below the mode: the bulk lies inside the object";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(118, 140, b, 1.5, 0.8, 0.6), 118) << "already above the reach";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 114, b, 1.5, 0.8, 0.6), 105) << "the crests inside the bulk";
  // 115 - 105 = 10 against 0.8 (crest - 105): raised with crests at 118, not at 116.
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 118, b, 1.5, 0.8, 0.6), 115);
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 116, b, 1.5, 0.8, 0.6), 105) << "the reach nearly at the crests";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 140, b, 2.0, 0.8, 0.6), 120) << "the spread sets the reach";
  // A wide hump (half-width 20, reach 130): from 125 with crests at 132 the
  // step (5 <= 0.8 x 7) passes and the width (20 > 0.6 x 32) does not.
  b.half_width = 20;
  EXPECT_DOUBLE_EQ(bulk_raised_iso(125, 132, b, 1.5, 0.8, 0.6), 125) << "no distinct bulk";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(125, 132, b, 1.5, 0.8, 1.0), 130) << "with the width's bound at 1";
  EXPECT_DOUBLE_EQ(bulk_raised_iso(125, 140, b, 1.5, 0.8, 0.6), 130) << "20 <= 0.6 x 40";
  b.half_width = 10;
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 140, b, 0.0, 0.8, 0.6), 105) << "spread 0: off";
  b.measured = false;
  EXPECT_DOUBLE_EQ(bulk_raised_iso(105, 140, b, 1.5, 0.8, 0.6), 105) << "nothing measured";
}

class CliBulk : public test::CliTest {};

// The `iso V` of classify's volume line.
double iso_of(const std::string& out) {
  std::smatch m;
  const std::regex re(" iso ([0-9.]+) \\(auto");
  return std::regex_search(out, m, re) ? std::stod(m[1]) : NAN;
}
// The shadow walls' report on the bone cue's line.
std::string walls_of(const std::string& out) {
  const std::size_t at = out.find("shadow walls:");
  return at == std::string::npos ? "" : out.substr(at, out.find('\n', at) - at);
}

TEST_F(CliBulk, ASpineIsRaisedAFaceIsNotAndTheSwitchTurnsItOff) {
  // A family spine in bright tissue (its isovalue from the edges lies in the
  // tissue's upper tail, its echoes above it) and the default face (fluid the
  // bulk, the isovalue far above it).
  ASSERT_EQ(run({"phantom", "--shape", "spine", "--physics", "random", "--seed", "119", "--size", "64", "-o",
                 file("spine"), "-q"})
                .status,
            0);
  ASSERT_EQ(run({"phantom", "--shape", "face", "--size", "64", "-o", file("face"), "-q"}).status, 0);
  const test::RunResult a = run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "-o", file("a.nrrd")});
  ASSERT_EQ(a.status, 0) << a.err;
  const std::regex said("raised from ([0-9.]+) above the bulk: its mode ([0-9.]+) \\+ 1.5 x its half-width ([0-9.]+), "
                        "the echoes' crests at ([0-9.]+)\\)");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(a.out, m, said)) << a.out;
  const double from = std::stod(m[1]), mode = std::stod(m[2]), half = std::stod(m[3]), crest = std::stod(m[4]);
  const double iso = iso_of(a.out);
  EXPECT_NEAR(iso, mode + 1.5 * half, 0.2) << a.out;
  EXPECT_GT(from, mode);
  EXPECT_LT(from, iso);
  EXPECT_GT(crest, iso);
  const test::RunResult off =
      run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "--iso-bulk-spread", "0", "-o", file("off.nrrd")});
  ASSERT_EQ(off.status, 0) << off.err;
  EXPECT_EQ(off.out.find("above the bulk"), std::string::npos) << off.out;
  EXPECT_NEAR(iso_of(off.out), from, 0.01) << "off: the edges' isovalue";
  EXPECT_NE(read_volume(file("a.nrrd")).data, read_volume(file("off.nrrd")).data);
  // The shadow test keeps the edges' isovalue either way.
  EXPECT_FALSE(walls_of(a.out).empty()) << a.out;
  EXPECT_EQ(walls_of(a.out), walls_of(off.out));
  const test::RunResult f = run({"classify", file("face/volume.nrrd"), "--iso", "auto", "-o", file("f.nrrd")});
  ASSERT_EQ(f.status, 0) << f.err;
  EXPECT_EQ(f.out.find("above the bulk"), std::string::npos) << f.out;
  expect_one_line_error(run({"classify", file("face/volume.nrrd"), "--iso-bulk-spread", "-1", "-o", file("x.nrrd")}),
                        {"--iso-bulk-spread"});
}

}  // namespace
}  // namespace softshell
