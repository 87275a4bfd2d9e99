// Surface-quality metrics (host/metrics.cpp) on known answers: opacity shells
// around an analytic sphere SDF (perfect, with a detached blob, shifted,
// half-shells that test the facing rule, randomly modulated, empty), the
// exact EDT against brute force, and `softshell evaluate` end to end.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "io.hpp"
#include "metrics.hpp"
#include "test_support.hpp"
#include "text.hpp"

namespace softshell {
namespace {

constexpr std::size_t kN = 48;
constexpr double kC = 24.0, kR = 15.0;

// sdf = |x - c| - r in voxels, negative inside.
Volume sphere_sdf(std::size_t n = kN, double c = kC, double r = kR) {
  Volume v({n, n, n});
  for (std::size_t z = 0; z < n; ++z)
    for (std::size_t y = 0; y < n; ++y)
      for (std::size_t x = 0; x < n; ++x)
        v.at(x, y, z) = float(std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c)) - r);
  return v;
}

// u = max(0, 1 - |sdf - shift| / 1.5): a soft shell 3 voxels thick, centred
// `shift` voxels outside the true surface.
Volume shell(const Volume& sdf, double shift = 0.0) {
  Volume u = sdf;
  for (float& f : u.data) f = float(std::max(0.0, 1.0 - std::abs(f - shift) / 1.5));
  return u;
}

// u = exp(-sdf^2 / (2 sigma^2)): a smooth shell, like the variational solution.
Volume smooth_shell(const Volume& sdf, double sigma = 2.0) {
  Volume u = sdf;
  for (float& f : u.data) f = float(std::exp(-double(f) * f / (2 * sigma * sigma)));
  return u;
}

// Keeps u only where keep(z) holds.
template <class Keep>
Volume cut(Volume u, Keep keep) {
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x)
        if (!keep(z)) u.at(x, y, z) = 0.0f;
  return u;
}

TEST(MetricsSphere, PerfectShellScoresPerfectly) {
  const Volume sdf = sphere_sdf();
  const Metrics m = evaluate_opacity(shell(sdf), sdf);
  EXPECT_DOUBLE_EQ(m.precision, 1.0);
  EXPECT_DOUBLE_EQ(m.recall, 1.0);
  EXPECT_EQ(m.spurious_blobs, 0u);
  EXPECT_EQ(m.spurious_voxels, 0u);
  EXPECT_EQ(m.components, 1u);
  // The tent's kink on its ridge (|sdf| < 1) bends central differences there: ~15 degrees. See
  // SmoothShellHasAccurateNormals and docs/metrics.md.
  EXPECT_LT(m.normal_error_deg, 20.0);
  EXPECT_GT(m.normal_voxels, 1000u);
  // Splats: voxels with |sdf| < 1.5 * (1 - 0.2); percent_opaque likewise with 0.01.
  std::size_t splats = 0, opaque = 0;
  for (float s : sdf.data) {
    splats += 1.0 - std::abs(s) / 1.5 > 0.2;
    opaque += 1.0 - std::abs(s) / 1.5 > 0.01;
  }
  EXPECT_EQ(m.splats, splats);
  EXPECT_NEAR(m.percent_opaque, 100.0 * double(opaque) / double(sdf.voxels()), 1e-9);
  // Facing cap n_z <= -0.3 of a sphere of radius 15: area 2 pi r^2 (1 - 0.3) of 4 pi r^2 -> 35 %
  // of the two-sided surface layer.
  std::size_t surface = 0;
  for (std::size_t z = 0; z < kN; ++z)
    for (std::size_t y = 0; y < kN; ++y)
      for (std::size_t x = 1; x < kN; ++x)
        if ((sdf.at(x, y, z) <= 0) != (sdf.at(x - 1, y, z) <= 0)) ++surface;
  EXPECT_GT(m.facing_surface_voxels, 0u);
  EXPECT_GT(m.facing_surface_voxels, surface / 2) << "a two-sided layer holds more voxels than x-crossings";
}

TEST(MetricsSphere, TensorOrientationIsRightOnTheRidgeOfAThinShell) {
  // The tent shell max(0, 1 - |sdf| / 1.5): on its middle sheet grad u is
  // undefined (central differences see only the variation along the
  // surface); the structure tensor takes both flanks and finds the normal.
  const Volume sdf = sphere_sdf();
  const Volume tent = shell(sdf);
  MetricsParams gradient, tensor;
  gradient.tensor_sigma = 0;
  tensor.tensor_sigma = 1.5;
  const Metrics g = evaluate_opacity(tent, sdf, gradient), t = evaluate_opacity(tent, sdf, tensor);
  EXPECT_GT(g.normal_error_deg, 10.0);
  EXPECT_LT(t.normal_error_deg, 0.5 * g.normal_error_deg) << "grad u: " << g.normal_error_deg;
  EXPECT_LT(t.normal_error_deg, 7.0) << "what remains is the sphere's curvature across the window";
  EXPECT_GE(t.normal_voxels, g.normal_voxels) << "the ridge voxels, skipped by grad u, count now";
}

TEST(MetricsSphere, SmoothShellHasAccurateNormals) {
  const Volume sdf = sphere_sdf();
  const Metrics smooth = evaluate_opacity(smooth_shell(sdf), sdf);
  const Metrics tent = evaluate_opacity(shell(sdf), sdf);
  EXPECT_LT(smooth.normal_error_deg, 3.0);
  EXPECT_GT(tent.normal_error_deg, smooth.normal_error_deg);
  EXPECT_DOUBLE_EQ(smooth.recall, 1.0);
  EXPECT_EQ(smooth.components, 1u);
  EXPECT_EQ(smooth.spurious_blobs, 0u);
  // Drawn out to |sdf| = 2 sqrt(2 ln 5) = 3.6 > the tolerance: some opacity lies too far out.
  EXPECT_GT(smooth.precision, 0.6);
  EXPECT_LT(smooth.precision, 1.0);
}

TEST(MetricsSphere, DetachedBlobIsOneSpuriousComponent) {
  const Volume sdf = sphere_sdf();
  Volume u = shell(sdf);
  const Metrics clean = evaluate_opacity(u, sdf);
  std::size_t blob = 0;
  for (std::size_t z = 3; z <= 9; ++z)
    for (std::size_t y = 3; y <= 9; ++y)
      for (std::size_t x = 3; x <= 9; ++x)
        if ((x - 6.0) * (x - 6.0) + (y - 6.0) * (y - 6.0) + (z - 6.0) * (z - 6.0) <= 4.0) {
          ASSERT_GT(sdf.at(x, y, z), 10.0f);
          u.at(x, y, z) = 1.0f;
          ++blob;
        }
  const Metrics m = evaluate_opacity(u, sdf);
  EXPECT_EQ(m.spurious_blobs, clean.spurious_blobs + 1);
  EXPECT_EQ(m.components, clean.components + 1);
  EXPECT_EQ(m.spurious_voxels, blob);
  EXPECT_EQ(m.splats, clean.splats + blob);
  EXPECT_LT(m.precision, 1.0);
  // The shell's drawn opacity is all near the surface, the blob's none of it.
  double shell_u = 0;
  for (float v : shell(sdf).data)
    if (v > 0.2f) shell_u += v;
  EXPECT_NEAR(m.precision, shell_u / (shell_u + double(blob)), 1e-12);
  EXPECT_DOUBLE_EQ(m.recall, 1.0);
}

TEST(MetricsSphere, ShellShiftedOutwardLosesPrecisionAndRecall) {
  const Volume sdf = sphere_sdf();
  const Metrics m = evaluate_opacity(shell(sdf, 4.0), sdf);
  EXPECT_LT(m.precision, 0.5);
  EXPECT_LT(m.recall, 0.5);
  EXPECT_EQ(m.components, 1u);
  EXPECT_EQ(m.spurious_blobs, 1u) << "no drawn voxel lies within 2 voxels of the surface";
  // A shift of 1 voxel, within the tolerance, keeps most of the precision and all of the recall.
  const Metrics one = evaluate_opacity(shell(sdf, 1.0), sdf);
  EXPECT_GT(one.precision, 0.5);
  EXPECT_DOUBLE_EQ(one.recall, 1.0);
}

TEST(MetricsSphere, OnlySurfacesFacingTheTransducerCountForRecall) {
  const Volume sdf = sphere_sdf();
  const Volume u = shell(sdf);
  // Transducer on z = 0, beam along +z: the near half (z < centre) faces it.
  const Metrics near_half = evaluate_opacity(cut(u, [](std::size_t z) { return z < kC; }), sdf);
  const Metrics far_half = evaluate_opacity(cut(u, [](std::size_t z) { return z > kC; }), sdf);
  EXPECT_GT(near_half.recall, 0.99);
  EXPECT_LT(far_half.recall, 0.01);
  EXPECT_EQ(near_half.facing_surface_voxels, far_half.facing_surface_voxels);
  // Turning the beam around (transducer on the far face) swaps the halves.
  MetricsParams up;
  up.beam = {0, 0, -1};
  EXPECT_LT(evaluate_opacity(cut(u, [](std::size_t z) { return z < kC; }), sdf, up).recall, 0.01);
  EXPECT_GT(evaluate_opacity(cut(u, [](std::size_t z) { return z > kC; }), sdf, up).recall, 0.99);
  // facing_cos = -1 counts every surface voxel: each half then recalls about half.
  MetricsParams all;
  all.facing_cos = -1;
  const Metrics m = evaluate_opacity(cut(u, [](std::size_t z) { return z < kC; }), sdf, all);
  EXPECT_GT(m.facing_surface_voxels, 2 * near_half.facing_surface_voxels);
  EXPECT_NEAR(m.recall, 0.5, 0.1);
}

TEST(MetricsSphere, RandomOpacityAlongTheSurfaceRaisesNormalError) {
  const Volume sdf = sphere_sdf();
  const Volume clean = smooth_shell(sdf, 1.5);
  Volume noisy = clean;
  std::mt19937_64 rng(test::seed());
  std::uniform_real_distribution<double> amp(0.3, 1.0);
  for (float& f : noisy.data) f = float(f * amp(rng));
  MetricsParams gradient;  // grad u orientation: sees every voxel's noise
  gradient.tensor_sigma = 0;
  const Metrics a = evaluate_opacity(clean, sdf, gradient), b = evaluate_opacity(noisy, sdf, gradient);
  EXPECT_GT(b.normal_error_deg, a.normal_error_deg + 10.0) << a.normal_error_deg << " vs " << b.normal_error_deg;
  EXPECT_LE(b.normal_error_deg, 90.0);
  EXPECT_GT(b.precision, a.precision) << "the damped outskirts fall below the threshold";
}

TEST(MetricsSphere, EmptyOpacityDrawsNothing) {
  const Volume sdf = sphere_sdf();
  Volume u = sdf;
  std::fill(u.data.begin(), u.data.end(), 0.0f);
  const Metrics m = evaluate_opacity(u, sdf);
  EXPECT_EQ(m.splats, 0u);
  EXPECT_EQ(m.recall, 0.0);
  EXPECT_EQ(m.precision, 0.0);
  EXPECT_EQ(m.components, 0u);
  EXPECT_EQ(m.spurious_blobs, 0u);
  EXPECT_EQ(m.normal_error_deg, 0.0);
  EXPECT_EQ(m.percent_opaque, 0.0);
  EXPECT_GT(m.facing_surface_voxels, 0u);
}

TEST(MetricsSphere, AnisotropicSpacingKeepsTheAnswers) {
  // The same shell sampled on a grid with 2 mm z spacing: the SDF is in voxels of x, and the
  // gradients are per mm, so a shell around an ellipsoid's true SDF still scores perfectly.
  const std::size_t nx = 40, nz = 24;
  const double c = 19.5, cz = 11.5, r = 12;
  Volume sdf({nx, nx, nz}, {1.0, 1.0, 2.0});
  for (std::size_t z = 0; z < nz; ++z)
    for (std::size_t y = 0; y < nx; ++y)
      for (std::size_t x = 0; x < nx; ++x) {
        const double dz = 2.0 * (z - cz);
        sdf.at(x, y, z) = float(std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + dz * dz) - r);
      }
  const Metrics m = evaluate_opacity(shell(sdf), sdf);
  EXPECT_DOUBLE_EQ(m.precision, 1.0);
  EXPECT_DOUBLE_EQ(m.recall, 1.0);
  EXPECT_EQ(m.components, 1u);
  EXPECT_EQ(m.spurious_blobs, 0u);
  // The smooth shell's normals stay close (z is sampled at 2 mm, half as finely as x and y).
  EXPECT_LT(evaluate_opacity(smooth_shell(sdf), sdf).normal_error_deg, 8.0);
  // Facing is judged in mm: the cap n_z <= -0.3 of the physical sphere, not of the voxel grid.
  std::size_t facing_lo = 0, facing_hi = 0, facing_grid = 0;
  for (std::size_t z = 0; z < nz; ++z)
    for (std::size_t y = 0; y < nx; ++y)
      for (std::size_t x = 0; x < nx; ++x) {
        const double px = x - c, py = y - c, pz = 2.0 * (z - cz), r3 = std::sqrt(px * px + py * py + pz * pz);
        bool surface = false;
        for (int a = 0; a < 3; ++a)
          for (int d = -1; d <= 1; d += 2) {
            std::size_t q[3] = {x, y, z};
            if ((d < 0 && q[a] == 0) || (d > 0 && q[a] + 1 == sdf.dims[a])) continue;
            q[a] += d;
            surface = surface || (sdf.at(q[0], q[1], q[2]) <= 0) != (sdf.at(x, y, z) <= 0);
          }
        facing_lo += surface && -pz / r3 >= 0.3 + 0.08;
        facing_hi += surface && -pz / r3 >= 0.3 - 0.05;
        // Read as if the voxels were cubes, the normal tilts toward z.
        facing_grid += surface && -2 * pz / std::sqrt(px * px + py * py + 4 * pz * pz) >= 0.3;
      }
  EXPECT_GE(m.facing_surface_voxels, facing_lo);
  EXPECT_LE(m.facing_surface_voxels, facing_hi);
  EXPECT_GT(facing_grid, facing_hi) << "the check does not tell mm from voxels";
}

TEST(Metrics, RejectsMismatchedDimsAndBadInput) {
  const Volume sdf = sphere_sdf(16, 8, 5);
  try {
    evaluate_opacity(Volume({16, 16, 15}), sdf);
    FAIL() << "no InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("dims differ: opacity 16x16x15 vs truth SDF 16x16x16"), std::string::npos)
        << e.what();
  }
  Volume u = shell(sdf);
  MetricsParams p;
  p.facing_cos = 1.5;
  EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError);
  p = {};
  p.beam = {0, 0, 0};
  EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError);
  p = {};
  p.tolerance = -1;
  EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError);
  u.data[5] = std::nanf("");
  EXPECT_THROW(evaluate_opacity(u, sdf), InputError);
}

TEST(Metrics, RepeatedRunsGiveIdenticalResults) {
  // Odd dims, threads picking slices in any order: partials are added in slice order, so two
  // runs agree to the last bit.
  const Volume sdf = sphere_sdf(37, 17.3, 11.1);
  Volume u = shell(sdf);
  std::mt19937_64 rng(test::seed());
  for (float& f : u.data) f = float(f * (0.5 + 0.5 * double(rng() >> 11) / 9007199254740992.0));
  const Metrics a = evaluate_opacity(u, sdf), b = evaluate_opacity(u, sdf);
  EXPECT_EQ(a.precision, b.precision);
  EXPECT_EQ(a.normal_error_deg, b.normal_error_deg);
  EXPECT_EQ(a.recall, b.recall);
}

// ---- exact EDT -----------------------------------------------------------

std::vector<double> brute_force_edt(const std::vector<unsigned char>& mask, const Dims3& d) {
  std::vector<double> out(mask.size(), std::numeric_limits<double>::infinity());
  for (std::size_t i = 0; i < mask.size(); ++i) {
    const double x = double(i % d[0]), y = double((i / d[0]) % d[1]), z = double(i / (d[0] * d[1]));
    for (std::size_t j = 0; j < mask.size(); ++j) {
      if (!mask[j]) continue;
      const double dx = x - double(j % d[0]), dy = y - double((j / d[0]) % d[1]), dz = z - double(j / (d[0] * d[1]));
      out[i] = std::min(out[i], dx * dx + dy * dy + dz * dz);
    }
  }
  return out;
}

TEST(MetricsEdt, MatchesBruteForceOnRandomMasks) {
  std::mt19937_64 rng(test::seed());
  for (const Dims3 d : {Dims3{13, 9, 11}, Dims3{1, 17, 5}, Dims3{20, 1, 1}, Dims3{7, 8, 19}}) {
    for (const double density : {0.002, 0.03, 0.3}) {
      std::vector<unsigned char> mask(d[0] * d[1] * d[2]);
      std::bernoulli_distribution set(density);
      for (auto& m : mask) m = set(rng);
      mask[rng() % mask.size()] = 1;  // never empty
      const auto got = metrics_detail::squared_edt(mask, d);
      const auto want = brute_force_edt(mask, d);
      SCOPED_TRACE(dims_text(d) + " density " + std::to_string(density));
      for (std::size_t i = 0; i < mask.size(); ++i)
        ASSERT_EQ(double(got[i]), want[i]) << "first difference at (" << i % d[0] << ", " << (i / d[0]) % d[1]
                                           << ", " << i / (d[0] * d[1]) << ")";
    }
  }
}

TEST(MetricsEdt, EmptyMaskIsInfiniteAndOneVoxelIsExact) {
  const Dims3 d{6, 5, 4};
  std::vector<unsigned char> mask(120, 0);
  for (float v : metrics_detail::squared_edt(mask, d)) EXPECT_TRUE(std::isinf(v));
  mask[0] = 1;  // voxel (0,0,0): the far corner is 5^2 + 4^2 + 3^2 = 50 away
  const auto got = metrics_detail::squared_edt(mask, d);
  EXPECT_EQ(got[0], 0.0f);
  EXPECT_EQ(got.back(), 50.0f);
}

// ---- `softshell evaluate` ----------------------------------------------------

// A minimal parser for a flat JSON object of numbers and arrays of numbers;
// fails the test on anything else or on trailing text.
std::map<std::string, std::vector<double>> parse_flat_json(const std::string& text) {
  std::map<std::string, std::vector<double>> out;
  std::size_t i = 0;
  const auto ws = [&] {
    while (i < text.size() && std::isspace(static_cast<unsigned char>(text[i]))) ++i;
  };
  const auto expect = [&](char c) {
    ws();
    if (i >= text.size() || text[i] != c) throw std::runtime_error(std::string("expected '") + c + "' at " + std::to_string(i));
    ++i;
  };
  const auto number = [&] {
    ws();
    const char* begin = text.c_str() + i;
    char* end = nullptr;
    const double v = std::strtod(begin, &end);
    if (end == begin) throw std::runtime_error("expected a number at " + std::to_string(i));
    i += std::size_t(end - begin);
    return v;
  };
  expect('{');
  for (;;) {
    expect('"');
    const std::size_t close = text.find('"', i);
    if (close == std::string::npos) throw std::runtime_error("unterminated key");
    const std::string key = text.substr(i, close - i);
    i = close + 1;
    expect(':');
    ws();
    std::vector<double> values;
    if (i < text.size() && text[i] == '[') {
      ++i;
      for (;;) {
        values.push_back(number());
        ws();
        if (i < text.size() && text[i] == ',') {
          ++i;
          continue;
        }
        expect(']');
        break;
      }
    } else {
      values.push_back(number());
    }
    if (!out.emplace(key, values).second) throw std::runtime_error("duplicate key " + key);
    ws();
    if (i < text.size() && text[i] == ',') {
      ++i;
      continue;
    }
    expect('}');
    break;
  }
  ws();
  if (i != text.size()) throw std::runtime_error("trailing text after the object");
  return out;
}

class CliEvaluate : public test::CliTest {};

TEST_F(CliEvaluate, JsonForAPerfectShell) {
  const Volume sdf = sphere_sdf();
  write_volume(file("truth.nrrd"), sdf);
  write_volume(file("u.nrrd"), shell(sdf));
  const test::RunResult r = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  ASSERT_FALSE(r.out.empty());
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << r.out;
  std::map<std::string, std::vector<double>> j;
  ASSERT_NO_THROW(j = parse_flat_json(r.out)) << r.out;
  for (const char* key : {"precision", "recall", "spurious_blobs", "components", "normal_error_deg",
                          "percent_opaque", "splats", "facing_surface_voxels", "threshold", "tolerance",
                          "facing_cos", "beam"})
    EXPECT_EQ(j.count(key), 1u) << key << " missing in " << r.out;
  const Metrics m = evaluate_opacity(shell(sdf), sdf);
  EXPECT_EQ(j["precision"], std::vector<double>{1.0});
  EXPECT_EQ(j["recall"], std::vector<double>{1.0});
  EXPECT_EQ(j["spurious_blobs"], std::vector<double>{0.0});
  EXPECT_EQ(j["components"], std::vector<double>{1.0});
  EXPECT_NEAR(j["normal_error_deg"].at(0), m.normal_error_deg, 1e-6);
  EXPECT_EQ(j["splats"], std::vector<double>{double(m.splats)});
  EXPECT_EQ(j["facing_surface_voxels"], std::vector<double>{double(m.facing_surface_voxels)});
  EXPECT_NEAR(j["percent_opaque"].at(0), m.percent_opaque, 1e-6);
  EXPECT_EQ(j["threshold"], std::vector<double>{0.2});
  EXPECT_EQ(j["tolerance"], std::vector<double>{2.0});
  EXPECT_EQ(j["facing_cos"], std::vector<double>{0.3});
  EXPECT_EQ(j["beam"], (std::vector<double>{0.0, 0.0, 1.0}));
  // Options reach the computation; the beam is reported as a unit vector.
  const test::RunResult o = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json", "--threshold", "0.5",
                                 "--tolerance", "1", "--beam", "0,0,-4", "--facing-cos", "0.5"});
  ASSERT_EQ(o.status, 0) << o.err;
  ASSERT_NO_THROW(j = parse_flat_json(o.out)) << o.out;
  MetricsParams p;
  p.threshold = 0.5;
  p.tolerance = 1;
  p.beam = {0, 0, -4};
  p.facing_cos = 0.5;
  const Metrics mo = evaluate_opacity(shell(sdf), sdf, p);
  EXPECT_EQ(j["splats"], std::vector<double>{double(mo.splats)});
  EXPECT_LT(mo.splats, m.splats);
  EXPECT_EQ(j["facing_surface_voxels"], std::vector<double>{double(mo.facing_surface_voxels)});
  EXPECT_EQ(j["beam"], (std::vector<double>{0.0, 0.0, -1.0}));
  EXPECT_EQ(j["threshold"], std::vector<double>{0.5});
}

TEST_F(CliEvaluate, TableNamesEveryMetric) {
  const Volume sdf = sphere_sdf(24, 12, 7);
  write_volume(file("truth.nrrd"), sdf);
  write_volume(file("u.mha"), shell(sdf));
  const test::RunResult r = run({"evaluate", file("u.mha"), file("truth.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* word : {"precision", "recall", "spurious_blobs", "components", "normal_error_deg",
                           "percent_opaque", "splats", "facing_surface_voxels", "24x24x24", "1.0000"})
    EXPECT_NE(r.out.find(word), std::string::npos) << word << " not in:\n" << r.out;
}

TEST_F(CliEvaluate, MismatchedDimsIsAOneLineError) {
  write_volume(file("truth.nrrd"), sphere_sdf(16, 8, 5));
  write_volume(file("u.nrrd"), shell(sphere_sdf(17, 8, 5)));
  const test::RunResult r = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json"});
  expect_one_line_error(r, {"dims differ: 17x17x17", "vs 16x16x16", "u.nrrd", "truth.nrrd"});
  EXPECT_TRUE(r.out.empty()) << r.out;
}

TEST_F(CliEvaluate, MissingFileAndBadOptionsAreOneLineErrors) {
  write_volume(file("truth.nrrd"), sphere_sdf(16, 8, 5));
  expect_one_line_error(run({"evaluate", file("nope.nrrd"), file("truth.nrrd")}), {"nope.nrrd"});
  expect_one_line_error(run({"evaluate", file("truth.nrrd"), file("gone.nrrd"), "--json"}), {"gone.nrrd"});
  const std::string t = file("truth.nrrd");
  expect_one_line_error(run({"evaluate", t, t, "--beam", "0,0,0"}), {"--beam"});
  expect_one_line_error(run({"evaluate", t, t, "--beam", "1,2"}), {"--beam"});
  expect_one_line_error(run({"evaluate", t, t, "--facing-cos", "1.5"}), {"--facing-cos"});
  expect_one_line_error(run({"evaluate", t, t, "--tolerance", "-1"}), {"--tolerance"});
  expect_one_line_error(run({"evaluate", t, t, "--threshold", "nan"}), {"--threshold"});
  expect_one_line_error(run({"evaluate", t}), {"TRUTH_SDF"});
}

}  // namespace
}  // namespace softshell
