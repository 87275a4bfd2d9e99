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
#include "orientation.hpp"
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
  // Splats: voxels with |sdf| < 1.5 * (1 - 0.2); percent_opaque likewise with the default 0.05.
  std::size_t splats = 0, opaque = 0;
  for (float s : sdf.data) {
    splats += 1.0 - std::abs(s) / 1.5 > 0.2;
    opaque += 1.0 - std::abs(s) / 1.5 > 0.05;
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

// A shadow volume of `inside` dB where x >= kC (the sphere's right half), `outside` elsewhere.
Volume half_shadow(const Volume& sdf, float inside, float outside = 0.0f) {
  Volume sh = sdf;
  for (std::size_t z = 0; z < sh.dims[2]; ++z)
    for (std::size_t y = 0; y < sh.dims[1]; ++y)
      for (std::size_t x = 0; x < sh.dims[0]; ++x) sh.at(x, y, z) = double(x) >= kC ? inside : outside;
  return sh;
}

TEST(MetricsVisible, RecallVisibleCountsOnlySurfacesOutOfTheShadow) {
  const Volume sdf = sphere_sdf();
  const Volume u = shell(sdf);
  // Only the left half drawn (x < kC), the right half in a 30 dB shadow.
  Volume left = u;
  for (std::size_t z = 0; z < kN; ++z)
    for (std::size_t y = 0; y < kN; ++y)
      for (std::size_t x = 0; x < kN; ++x)
        if (double(x) >= kC) left.at(x, y, z) = 0.0f;
  const Volume shadow = half_shadow(sdf, 30.0f);
  MetricsParams p;
  p.shadow_db = &shadow;
  const Metrics m = evaluate_opacity(left, sdf, p);
  const Metrics plain = evaluate_opacity(left, sdf);
  // recall is unchanged by the shadow volume; only the new key sees it.
  EXPECT_EQ(m.recall, plain.recall);
  EXPECT_TRUE(std::isnan(plain.recall_visible));
  EXPECT_EQ(plain.visible_surface_voxels, 0u);
  // The left half of the facing cap: x < 24 of a sphere centred at 24 (the
  // plane x = 24 itself lies in the shadow), so a bit less than half.
  std::size_t left_facing = 0;
  {
    // Independent count: facing surface voxels with x < kC, from the
    // metric's own definition on the analytic sphere (6-neighbour sign
    // change, outward normal n_z <= -0.3).
    for (std::size_t z = 1; z + 1 < kN; ++z)
      for (std::size_t y = 1; y + 1 < kN; ++y)
        for (std::size_t x = 1; x + 1 < kN; ++x) {
          const bool in = sdf.at(x, y, z) <= 0;
          const bool surface = (sdf.at(x - 1, y, z) <= 0) != in || (sdf.at(x + 1, y, z) <= 0) != in ||
                               (sdf.at(x, y - 1, z) <= 0) != in || (sdf.at(x, y + 1, z) <= 0) != in ||
                               (sdf.at(x, y, z - 1) <= 0) != in || (sdf.at(x, y, z + 1) <= 0) != in;
          const double dx = double(x) - kC, dy = double(y) - kC, dz = double(z) - kC;
          const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
          if (surface && r > 0 && -dz / r >= 0.3 && double(x) < kC) ++left_facing;
        }
  }
  EXPECT_NEAR(double(m.visible_surface_voxels), double(left_facing), 0.02 * double(left_facing));
  EXPECT_LT(m.visible_surface_voxels, m.facing_surface_voxels / 2 + 1);
  EXPECT_GT(m.visible_surface_voxels, m.facing_surface_voxels / 3);
  EXPECT_GT(m.recall_visible, 0.99);  // every visible surface voxel is drawn
  EXPECT_LT(m.recall, 0.6);           // the shadowed half is not
  // The same restriction for f1 and surface_peak: the visible half peaks as
  // the whole shell would, the shadowed half (at 0) is left out of the median.
  EXPECT_TRUE(std::isnan(plain.f1_visible));
  EXPECT_TRUE(std::isnan(plain.surface_peak_visible));
  EXPECT_NEAR(m.f1_visible, 2 * m.precision * m.recall_visible / (m.precision + m.recall_visible), 1e-12);
  EXPECT_GT(m.f1_visible, m.f1);
  const Metrics whole = evaluate_opacity(u, sdf, p);
  EXPECT_LT(m.surface_peak, 0.5 * whole.surface_peak);  // most facing voxels unpeaked
  EXPECT_NEAR(m.surface_peak_visible, whole.surface_peak, 0.05);
  // The shadowed half drawn instead: nothing visible is recalled (at a
  // tolerance of 0 voxels; at 2 the seam's neighbours count).
  Volume right = u;
  for (std::size_t i = 0; i < right.data.size(); ++i) right.data[i] -= left.data[i];
  MetricsParams p0 = p;
  p0.tolerance = 0;
  EXPECT_EQ(evaluate_opacity(right, sdf, p0).recall_visible, 0.0);
  EXPECT_EQ(evaluate_opacity(left, sdf, p0).recall_visible, 1.0);
  // The bound is strict (below visible_db): 20 dB everywhere hides every
  // surface (recall_visible undefined), 19.9 dB none (recall_visible = recall).
  const Volume at20 = half_shadow(sdf, 20.0f, 20.0f), below20 = half_shadow(sdf, 19.9f, 19.9f);
  p.shadow_db = &at20;
  const Metrics none = evaluate_opacity(left, sdf, p);
  EXPECT_EQ(none.visible_surface_voxels, 0u);
  EXPECT_TRUE(std::isnan(none.recall_visible));
  EXPECT_TRUE(std::isnan(none.f1_visible));
  EXPECT_TRUE(std::isnan(none.surface_peak_visible));
  p.shadow_db = &below20;
  const Metrics all = evaluate_opacity(left, sdf, p);
  EXPECT_EQ(all.visible_surface_voxels, all.facing_surface_voxels);
  EXPECT_EQ(all.recall_visible, all.recall);
  // visible_db moves the bound.
  p.shadow_db = &shadow;
  p.visible_db = 40;
  EXPECT_EQ(evaluate_opacity(left, sdf, p).visible_surface_voxels, m.facing_surface_voxels);
  // A shadow volume of other dims is refused.
  const Volume small = sphere_sdf(16, 8, 5);
  p.shadow_db = &small;
  EXPECT_THROW(evaluate_opacity(left, sdf, p), InputError);
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

TEST(MetricsSphere, OrientationByTheDataScoresTheDatasNormals) {
  // u is a shell striped along x (opacity 0.1-1 with a period of 7
  // voxels): the stripes' gradients, along the surface, tilt u's own tensor;
  // the orientation field is a clean radial field (a smooth step across the
  // sphere), whose tensor is right: scored with it, the error falls to a few
  // degrees. A field of parallel planes scores as badly as its tilt.
  const Volume sdf = sphere_sdf();
  Volume u = smooth_shell(sdf, 1.5);
  Volume radial = sdf, planes = sdf;
  for (std::size_t i = 0; i < sdf.voxels(); ++i) {
    const double x = double(i % kN);
    u.data[i] = float(u.data[i] * (0.55 + 0.45 * std::sin(0.9 * x)));
    radial.data[i] = float(200.0 / (1.0 + std::exp(double(sdf.data[i]) / 2.0)));
    planes.data[i] = float(x);
  }
  const Metrics by_u = evaluate_opacity(u, sdf);
  MetricsParams p;
  p.orientation_field = &radial;
  const Metrics by_data = evaluate_opacity(u, sdf, p);
  EXPECT_LT(by_data.normal_error_deg, 5.0);
  EXPECT_GT(by_u.normal_error_deg, by_data.normal_error_deg + 5.0) << by_u.normal_error_deg;
  EXPECT_EQ(by_data.normal_voxels, by_u.normal_voxels) << "the same voxels, other normals";
  EXPECT_EQ(by_data.precision, by_u.precision);
  EXPECT_EQ(by_data.f1, by_u.f1);
  p.orientation_field = &planes;
  EXPECT_GT(evaluate_opacity(u, sdf, p).normal_error_deg, 40.0);
  // A field of other dims, or the gradient orientation with a field: input errors.
  const Volume small = sphere_sdf(16, 8, 5);
  p.orientation_field = &small;
  EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError);
  p.orientation_field = &radial;
  p.tensor_sigma = 0;
  EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError);
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
  EXPECT_EQ(m.mass_precision, 0.0);
  EXPECT_EQ(m.f1, 0.0);
  EXPECT_EQ(m.f1_mass, 0.0);
  EXPECT_EQ(m.surface_peak, 0.0) << "every facing point is a hole";
  EXPECT_EQ(m.shell_thickness_mm, 0.0);
  EXPECT_EQ(m.thickness_points, 0u);
  EXPECT_EQ(m.blobs6, 0u);
  EXPECT_EQ(m.components6, 0u);
  EXPECT_EQ(m.blob6_voxel_share, 0.0);
  EXPECT_EQ(m.blob_threshold, 0.0);
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

// ---- metrics that see all of u (mass precision, surface peak, thickness, 6-connected blobs) ----

constexpr double kFwhmPerSigma = 2.3548200450309493;  // 2 sqrt(2 ln 2)

// The same shell in a volume whose every voxel is h mm (the SDF stays in voxels).
Volume with_spacing(Volume v, const Vec3d& h) {
  v.spacing = h;
  return v;
}

// Independent serial sums: share of sum u with |sdf| <= tol.
double mass_share(const Volume& u, const Volume& sdf, double tol) {
  double near = 0, all = 0;
  for (std::size_t i = 0; i < u.data.size(); ++i) {
    all += u.data[i];
    if (std::abs(sdf.data[i]) <= tol) near += u.data[i];
  }
  return near / all;
}

TEST(MetricsShell, GaussianShellHasItsFullWidthAtHalfMaximumAndPeak) {
  // u = exp(-sdf^2 / 2 s^2) has FWHM 2.3548 s and peak 1 on the surface. Trilinear sampling
  // between voxel centres blurs a little: +1.8 % and peak 0.983 at s = 2, +0.9 % and 0.992 at s = 3.
  const Volume sdf = sphere_sdf();
  for (const double sigma : {2.0, 3.0}) {
    SCOPED_TRACE("sigma " + std::to_string(sigma));
    const Metrics m = evaluate_opacity(smooth_shell(sdf, sigma), sdf);
    EXPECT_NEAR(m.shell_thickness_mm, kFwhmPerSigma * sigma, 0.025 * kFwhmPerSigma * sigma);
    EXPECT_GT(m.surface_peak, 0.97);
    EXPECT_LE(m.surface_peak, 1.0);
    EXPECT_EQ(m.thickness_points, m.facing_surface_voxels) << "every facing point has a measurable shell";
    EXPECT_EQ(m.thickness_censored, 0u);
    EXPECT_EQ(m.profile_radius_mm, 6.0) << "max(6 voxels, 4 mm) at 1 mm";
  }
  // Wider is wider: the width follows sigma.
  const double w15 = evaluate_opacity(smooth_shell(sdf, 1.5), sdf).shell_thickness_mm;
  const double w3 = evaluate_opacity(smooth_shell(sdf, 3.0), sdf).shell_thickness_mm;
  EXPECT_NEAR(w3 / w15, 2.0, 0.1);
}

TEST(MetricsShell, ShellOffsetIsWhereAcrossTheSurfaceTheShellLies) {
  // u = exp(-(sdf - c)^2 / 2 s^2): the shell's middle lies c voxels outside the truth (c < 0:
  // inside), whatever its width; at 1 mm per voxel that is c mm. Trilinear sampling and the
  // sphere's curvature move it by a few hundredths.
  const Volume sdf = sphere_sdf();
  for (const double c : {0.0, 1.5, -1.0, 2.5}) {
    for (const double sigma : {1.5, 2.5}) {
      SCOPED_TRACE("c " + std::to_string(c) + ", sigma " + std::to_string(sigma));
      Volume u = sdf;
      for (float& f : u.data) f = float(std::exp(-(double(f) - c) * (double(f) - c) / (2 * sigma * sigma)));
      const Metrics m = evaluate_opacity(u, sdf);
      EXPECT_NEAR(m.shell_offset_mm, c, 0.1);
      EXPECT_GT(m.offset_points, m.facing_surface_voxels / 2);
      EXPECT_LE(m.offset_points, m.thickness_points);
    }
  }
  // In millimetres: the same voxels at 0.5 mm halve it.
  Volume u = sdf;
  for (float& f : u.data) f = float(std::exp(-(double(f) - 1.5) * (double(f) - 1.5) / 8.0));
  const double one = evaluate_opacity(u, sdf).shell_offset_mm;
  EXPECT_NEAR(evaluate_opacity(with_spacing(u, {0.5, 0.5, 0.5}), with_spacing(sdf, {0.5, 0.5, 0.5})).shell_offset_mm,
              0.5 * one, 1e-9);
  // Nothing drawn: no interval, no offset (null in the JSON).
  Volume empty = sdf;
  for (float& f : empty.data) f = 0.0f;
  const Metrics e = evaluate_opacity(empty, sdf);
  EXPECT_TRUE(std::isnan(e.shell_offset_mm));
  EXPECT_EQ(e.offset_points, 0u);
  EXPECT_NE(metrics_json(e, MetricsParams{}).find("\"shell_offset_mm\": null"), std::string::npos);
}

TEST(MetricsShell, ThicknessIsInMillimetres) {
  // The same voxels at 0.5 mm: every length halves exactly (the profile steps 0.1 voxel either way).
  const Volume sdf = sphere_sdf();
  const Volume u = smooth_shell(sdf, 2.0);
  const Metrics one = evaluate_opacity(u, sdf);
  const Metrics half = evaluate_opacity(with_spacing(u, {0.5, 0.5, 0.5}), with_spacing(sdf, {0.5, 0.5, 0.5}));
  EXPECT_NEAR(half.shell_thickness_mm, 0.5 * one.shell_thickness_mm, 1e-9);
  EXPECT_EQ(half.surface_peak, one.surface_peak);
  EXPECT_EQ(half.tolerance, 2.0) << "--tolerance is in voxels";
  EXPECT_EQ(half.tolerance_mm, 1.0);
  EXPECT_EQ(half.profile_radius_mm, 4.0) << "max(6 voxels = 3 mm, 4 mm)";

  // Anisotropic 1 x 1 x 2 mm voxels around a physical sphere (SDF in units of the smallest
  // spacing, 1 mm) with a Gaussian shell of sigma 2 mm: FWHM 4.71 mm along the physical normal.
  // The facing cap points along z, where the samples are 2 mm apart: a coarser blur (+4 %).
  const std::size_t nx = 48, nz = 24;
  const double c = 23.5, cz = 11.5, r = 15;
  Volume asdf({nx, nx, nz}, {1.0, 1.0, 2.0});
  for (std::size_t z = 0; z < nz; ++z)
    for (std::size_t y = 0; y < nx; ++y)
      for (std::size_t x = 0; x < nx; ++x) {
        const double dz = 2.0 * (z - cz);
        asdf.at(x, y, z) = float(std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + dz * dz) - r);
      }
  const Metrics a = evaluate_opacity(smooth_shell(asdf, 2.0), asdf);
  EXPECT_NEAR(a.shell_thickness_mm, kFwhmPerSigma * 2.0, 0.06 * kFwhmPerSigma * 2.0);
  EXPECT_GT(a.surface_peak, 0.95);
  EXPECT_EQ(a.thickness_points, a.facing_surface_voxels);
  // Read as 1 mm cubes (ignoring the 2 mm z spacing), the same field would be half as thick
  // along z: the measurement must not be that.
  Volume cubes = smooth_shell(asdf, 2.0);
  cubes.spacing = {1.0, 1.0, 1.0};
  Volume cube_sdf = asdf;
  cube_sdf.spacing = {1.0, 1.0, 1.0};
  EXPECT_LT(evaluate_opacity(cubes, cube_sdf).shell_thickness_mm, 0.8 * a.shell_thickness_mm);
}

TEST(MetricsShell, SurfacePeakIsAFractionOfUInd) {
  const Volume sdf = sphere_sdf();
  const Volume full = smooth_shell(sdf, 2.0);
  Volume dim = full;
  for (float& f : dim.data) f *= 0.55f;
  const Metrics a = evaluate_opacity(full, sdf), b = evaluate_opacity(dim, sdf);
  // Trilinear sampling and the median are linear in u: the peak scales exactly, the width not at all.
  EXPECT_NEAR(b.surface_peak, 0.55 * a.surface_peak, 1e-6);
  EXPECT_NEAR(b.surface_peak, 0.55, 0.02);
  EXPECT_NEAR(b.shell_thickness_mm, a.shell_thickness_mm, 1e-4);
  // Measured against u_ind = 0.55 the dim shell reaches its target.
  MetricsParams p;
  p.u_ind = 0.55;
  EXPECT_NEAR(evaluate_opacity(dim, sdf, p).surface_peak, a.surface_peak, 1e-6);
  // Precision and recall do not see the difference (the dim shell is still drawn where it
  // exceeds 0.2); percent_opaque and splats do.
  EXPECT_EQ(b.recall, a.recall);
  EXPECT_LT(b.splats, a.splats);
}

TEST(MetricsShell, HolesInTheShellLowerTheMedianPeakOnceMoreThanHalfIsMissing) {
  const Volume sdf = sphere_sdf();
  const Volume u = smooth_shell(sdf, 2.0);
  const auto holes = [&](double x_cut) {
    Volume h = u;
    for (std::size_t z = 0; z < kN; ++z)
      for (std::size_t y = 0; y < kN; ++y)
        for (std::size_t x = 0; x < kN; ++x)
          if (double(x) < x_cut) h.at(x, y, z) = 0.0f;
    return evaluate_opacity(h, sdf);
  };
  const Metrics whole = evaluate_opacity(u, sdf);
  // The facing cap is symmetric about x = 24: cutting x < 21 removes well under half of it,
  // x < 27 well over half.
  const Metrics some = holes(21.0), most = holes(27.0);
  EXPECT_NEAR(some.surface_peak, whole.surface_peak, 0.02) << "the median still sees the shell";
  EXPECT_LT(most.surface_peak, 0.05) << "the median sees the holes";
  EXPECT_LT(most.thickness_points, whole.thickness_points / 2) << "holes have no width to measure";
  EXPECT_EQ(most.facing_surface_voxels, whole.facing_surface_voxels);
}

TEST(MetricsShell, ShellsTooFaintOrTooWideToMeasureAreCounted) {
  const Volume sdf = sphere_sdf();
  // A peak below 0.05 u_ind: no width is measured; the peak still counts.
  Volume faint = smooth_shell(sdf, 2.0);
  for (float& f : faint.data) f *= 0.04f;
  const Metrics f = evaluate_opacity(faint, sdf);
  EXPECT_EQ(f.thickness_points, 0u);
  EXPECT_EQ(f.thickness_censored, 0u);
  EXPECT_EQ(f.shell_thickness_mm, 0.0);
  EXPECT_NEAR(f.surface_peak, 0.04, 0.002);
  // sigma 6: FWHM 14 voxels, its half-maximum crossings 7 voxels out, beyond the +-6 voxel
  // window: every width is censored and enters as the window's 12 voxels, a lower bound (the
  // widest shells must not drop out of the median and leave it to the thin ones).
  const Metrics w = evaluate_opacity(smooth_shell(sdf, 6.0), sdf);
  EXPECT_EQ(w.thickness_points, w.facing_surface_voxels);
  EXPECT_EQ(w.thickness_censored, w.facing_surface_voxels);
  EXPECT_NEAR(w.shell_thickness_mm, 12.0, 1e-9);
  EXPECT_GT(w.surface_peak, 0.99);
  // At 0.25 mm voxels the window is 4 mm = 16 voxels: the same field is measured, 14 voxels.
  const Metrics fine = evaluate_opacity(with_spacing(smooth_shell(sdf, 6.0), {0.25, 0.25, 0.25}),
                                        with_spacing(sdf, {0.25, 0.25, 0.25}));
  EXPECT_EQ(fine.thickness_censored, 0u);
  EXPECT_NEAR(fine.shell_thickness_mm, 0.25 * kFwhmPerSigma * 6.0, 0.02 * 0.25 * kFwhmPerSigma * 6.0);
  // Half wide, half thin: the median sits at the boundary of the two groups, not at the thin one.
  Volume mixed = smooth_shell(sdf, 1.5);
  const Volume wide = smooth_shell(sdf, 6.0);
  for (std::size_t z = 0; z < kN; ++z)
    for (std::size_t y = 0; y < kN; ++y)
      for (std::size_t x = 0; x < kN; ++x)
        if (x < 21) mixed.at(x, y, z) = wide.at(x, y, z);  // under half of the facing cap
  const Metrics mx = evaluate_opacity(mixed, sdf);
  EXPECT_GT(mx.thickness_censored, mx.thickness_points / 4);
  EXPECT_LT(mx.shell_thickness_mm, 5.0) << "the thin part is the majority";
  for (std::size_t z = 0; z < kN; ++z)
    for (std::size_t y = 0; y < kN; ++y)
      for (std::size_t x = 0; x < kN; ++x)
        if (x < 28) mixed.at(x, y, z) = wide.at(x, y, z);  // over half
  EXPECT_GT(evaluate_opacity(mixed, sdf).shell_thickness_mm, 10.0) << "the wide part is the majority";
}

TEST(MetricsMass, UniformHazeLowersMassPrecisionOnly) {
  const Volume sdf = sphere_sdf();
  const Volume clean = shell(sdf);
  Volume hazy = clean;
  for (float& f : hazy.data) f += 0.03f;
  const Metrics a = evaluate_opacity(clean, sdf), b = evaluate_opacity(hazy, sdf);
  EXPECT_DOUBLE_EQ(a.mass_precision, 1.0) << "the tent lies within |sdf| < 1.5 <= 2";
  // The haze adds 0.03 to every voxel: sum u grows by 0.03 N, the near part by 0.03 |near|.
  double shell_mass = 0;
  std::size_t near = 0;
  for (std::size_t i = 0; i < sdf.data.size(); ++i) {
    shell_mass += clean.data[i];
    near += std::abs(sdf.data[i]) <= 2.0f;
  }
  const double n = double(sdf.voxels()), haze_near = 0.03 * double(near);
  EXPECT_NEAR(b.mass_precision, (shell_mass + haze_near) / (shell_mass + 0.03 * n), 1e-5);
  EXPECT_NEAR(b.mass_precision, mass_share(hazy, sdf, 2.0), 1e-9);
  // 0.03 over 48^3 voxels is 3318, nearly as much as the shell's 4900: 0.61.
  EXPECT_LT(b.mass_precision, 0.65);
  // The thresholded precision cannot see it: every drawn voxel (|sdf| < 1.245) is still near.
  EXPECT_DOUBLE_EQ(b.precision, 1.0);
  EXPECT_DOUBLE_EQ(b.f1, 1.0);
  EXPECT_LT(b.f1_mass, 0.8);
  EXPECT_NEAR(b.f1_mass, 2 * b.mass_precision * b.recall / (b.mass_precision + b.recall), 1e-12);
  EXPECT_EQ(b.blobs6, 0u) << "0.03 is below 0.2 max u";
}

TEST(MetricsMass, ShiftedShellLosesMassPrecision) {
  const Volume sdf = sphere_sdf();
  const Volume shifted = shell(sdf, 3.0);  // 1.5 < sdf < 4.5: only 1.5 < sdf <= 2 is near
  const Metrics m = evaluate_opacity(shifted, sdf);
  EXPECT_NEAR(m.mass_precision, mass_share(shifted, sdf, 2.0), 1e-9);
  // A flat shell would keep 1/18 of its mass (a triangle of height 1/3 and base 0.5 of one
  // with height 1 and base 3); the sphere's inner side is smaller.
  EXPECT_GT(m.mass_precision, 0.03);
  EXPECT_LT(m.mass_precision, 1.0 / 18.0);
  EXPECT_LT(m.f1_mass, 0.2);
  // Its peak within 2 voxels of the surface is the tent's flank, u(2) = 1/3.
  EXPECT_NEAR(m.surface_peak, 1.0 / 3.0, 0.04);
}

TEST(MetricsMass, PhysicalToleranceScoresTheSameAnatomyAlikeAtTwoResolutions) {
  // A sphere of radius 10 mm at 1 mm (32^3) and at 0.5 mm (64^3), each SDF in its own voxels;
  // a Gaussian shell of sigma 1.5 mm; scored with a 2 mm tolerance.
  MetricsParams p;
  p.tolerance_mm = 2.0;
  Metrics m[2];
  for (int k = 0; k < 2; ++k) {
    const double h = k == 0 ? 1.0 : 0.5;
    const std::size_t n = k == 0 ? 32 : 64;
    const Volume sdf = with_spacing(sphere_sdf(n, 0.5 * (double(n) - 1), 10.0 / h), {h, h, h});
    const Volume u = with_spacing(smooth_shell(sdf, 1.5 / h), {h, h, h});
    m[k] = evaluate_opacity(u, sdf, p);
    EXPECT_EQ(m[k].tolerance, 2.0 / h);
    EXPECT_EQ(m[k].tolerance_mm, 2.0);
    EXPECT_NEAR(m[k].mass_precision, mass_share(u, sdf, 2.0 / h), 1e-9);
  }
  EXPECT_NEAR(m[0].mass_precision, m[1].mass_precision, 0.01);
  EXPECT_NEAR(m[0].precision, m[1].precision, 0.03);
  EXPECT_NEAR(m[0].shell_thickness_mm, kFwhmPerSigma * 1.5, 0.05 * kFwhmPerSigma * 1.5);
  EXPECT_NEAR(m[1].shell_thickness_mm, kFwhmPerSigma * 1.5, 0.02 * kFwhmPerSigma * 1.5);
  // The voxel tolerance would score the finer volume against a 1 mm band instead.
  const double h = 0.5;
  const Volume sdf = with_spacing(sphere_sdf(64, 31.5, 20.0), {h, h, h});
  EXPECT_LT(evaluate_opacity(with_spacing(smooth_shell(sdf, 3.0), {h, h, h}), sdf).mass_precision,
            m[1].mass_precision - 0.2);
  // Anisotropic: the smallest spacing converts.
  Volume a = with_spacing(sphere_sdf(16, 8, 5), {0.5, 0.75, 1.0});
  const Metrics ma = evaluate_opacity(with_spacing(shell(a), a.spacing), a, p);
  EXPECT_EQ(ma.tolerance, 4.0);
  EXPECT_EQ(ma.tolerance_mm, 2.0);
}

TEST(MetricsBlobs, DiagonalChainIsOneBlobAt26AndManyAt6) {
  const Volume sdf = sphere_sdf();
  const Volume clean = shell(sdf);
  Volume u = clean;
  const std::size_t chain = 8;  // (2,2,2) ... (9,9,9): corners touch, faces do not
  for (std::size_t i = 0; i < chain; ++i) {
    ASSERT_GT(sdf.at(2 + i, 2 + i, 2 + i), 10.0f);
    u.at(2 + i, 2 + i, 2 + i) = 1.0f;
  }
  const Metrics a = evaluate_opacity(clean, sdf), b = evaluate_opacity(u, sdf);
  EXPECT_EQ(a.blobs6, 0u);
  EXPECT_EQ(a.components6, 1u);
  EXPECT_EQ(b.spurious_blobs, a.spurious_blobs + 1);
  EXPECT_EQ(b.components, a.components + 1);
  EXPECT_EQ(b.blobs6, chain);
  EXPECT_EQ(b.components6, a.components6 + chain);
  EXPECT_EQ(b.blob_threshold, 0.2) << "0.2 x max u = 1";
  // Share: the chain's voxels among all with u > 0.2 (the shell's splats and the chain).
  EXPECT_NEAR(b.blob6_voxel_share, double(chain) / double(a.splats + chain), 1e-12);
  EXPECT_EQ(b.splats, a.splats + chain);
}

TEST(MetricsBlobs, RelativeThresholdSeesDimDebris) {
  // A shell of peak 0.5 and a ball of u = 0.15 far from it: below the absolute splat
  // threshold 0.2, above 0.2 x max u = 0.1.
  const Volume sdf = sphere_sdf();
  Volume u = shell(sdf);
  for (float& f : u.data) f *= 0.5f;
  std::size_t ball = 0;
  for (std::size_t z = 3; z <= 9; ++z)
    for (std::size_t y = 3; y <= 9; ++y)
      for (std::size_t x = 3; x <= 9; ++x)
        if ((x - 6.0) * (x - 6.0) + (y - 6.0) * (y - 6.0) + (z - 6.0) * (z - 6.0) <= 4.0) {
          u.at(x, y, z) = 0.15f;
          ++ball;
        }
  const Metrics m = evaluate_opacity(u, sdf);
  EXPECT_EQ(m.spurious_blobs, 0u) << "invisible at the absolute threshold";
  EXPECT_EQ(m.blobs6, 1u);
  EXPECT_EQ(m.components6, 2u);
  EXPECT_NEAR(m.blob_threshold, 0.1, 1e-7);
  std::size_t bright = 0;
  for (float f : u.data) bright += double(f) > m.blob_threshold;
  EXPECT_NEAR(m.blob6_voxel_share, double(ball) / double(bright), 1e-12);
  // blob_rel = 0.5: u > 0.25 keeps the shell's ridge only and drops the ball.
  MetricsParams p;
  p.blob_rel = 0.5;
  const Metrics q = evaluate_opacity(u, sdf, p);
  EXPECT_EQ(q.blobs6, 0u);
  EXPECT_EQ(q.blob6_voxel_share, 0.0);
  EXPECT_NEAR(q.blob_threshold, 0.25, 1e-7);
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
  for (const double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(), std::nan("")}) {
    p = {};
    p.u_ind = bad;
    EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError) << "u_ind " << bad;
  }
  for (const double bad : {0.0, -0.1, 1.01, std::nan("")}) {
    p = {};
    p.blob_rel = bad;
    EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError) << "blob_rel " << bad;
  }
  for (const double bad : {-1.0, std::numeric_limits<double>::infinity(), std::nan("")}) {
    p = {};
    p.tolerance_mm = bad;
    EXPECT_THROW(evaluate_opacity(u, sdf, p), InputError) << "tolerance_mm " << bad;
  }
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
  EXPECT_EQ(a.mass_precision, b.mass_precision);
  EXPECT_EQ(a.surface_peak, b.surface_peak);
  EXPECT_EQ(a.shell_thickness_mm, b.shell_thickness_mm);
  EXPECT_EQ(a.thickness_points, b.thickness_points);
  EXPECT_EQ(a.blobs6, b.blobs6);
  EXPECT_EQ(a.blob6_voxel_share, b.blob6_voxel_share);
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

// A minimal parser for a flat JSON object of numbers, arrays of numbers and
// strings (these into `strings` when given); throws on anything else or on
// trailing text.
std::map<std::string, std::vector<double>> parse_flat_json(const std::string& text,
                                                           std::map<std::string, std::string>* strings = nullptr) {
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
    if (text.compare(i, 4, "null") == 0) {  // JSON's null: a metric that was not computed
      i += 4;
      return std::numeric_limits<double>::quiet_NaN();
    }
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
    bool is_string = false;
    if (i < text.size() && text[i] == '"') {  // a string value (no escapes in softshell's): into `strings`
      const std::size_t end = text.find('"', i + 1);
      if (end == std::string::npos) throw std::runtime_error("unterminated string");
      if (strings && !strings->emplace(key, text.substr(i + 1, end - i - 1)).second)
        throw std::runtime_error("duplicate key " + key);
      i = end + 1;
      is_string = true;
    } else if (i < text.size() && text[i] == '[') {
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
    if (!is_string && !out.emplace(key, values).second) throw std::runtime_error("duplicate key " + key);
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
                          "facing_cos", "beam", "mass_precision", "f1", "f1_mass", "surface_peak",
                          "shell_thickness_mm", "thickness_points", "thickness_censored", "shell_offset_mm", "offset_points",
                          "blobs6", "components6",
                          "blob6_voxel_share", "blob_threshold", "tolerance_mm", "u_ind", "blob_rel", "opaque",
                          "profile_radius_mm"})
    EXPECT_EQ(j.count(key), 1u) << key << " missing in " << r.out;
  const Metrics m = evaluate_opacity(shell(sdf), sdf);
  EXPECT_EQ(j["precision"], std::vector<double>{1.0});
  EXPECT_EQ(j["recall"], std::vector<double>{1.0});
  EXPECT_EQ(j["spurious_blobs"], std::vector<double>{0.0});
  EXPECT_EQ(j["components"], std::vector<double>{1.0});
  EXPECT_NEAR(j["normal_error_deg"].at(0), m.normal_error_deg, 1e-6);
  EXPECT_EQ(j["splats"], std::vector<double>{double(m.splats)});
  EXPECT_EQ(j["facing_surface_voxels"], std::vector<double>{double(m.facing_surface_voxels)});
  EXPECT_NEAR(j["shell_offset_mm"].at(0), m.shell_offset_mm, 1e-6);
  EXPECT_EQ(j["offset_points"], std::vector<double>{double(m.offset_points)});
  EXPECT_NEAR(j["percent_opaque"].at(0), m.percent_opaque, 1e-6);
  EXPECT_EQ(j["threshold"], std::vector<double>{0.2});
  EXPECT_EQ(j["tolerance"], std::vector<double>{2.0});
  EXPECT_EQ(j["facing_cos"], std::vector<double>{0.3});
  EXPECT_EQ(j["beam"], (std::vector<double>{0.0, 0.0, 1.0}));
  EXPECT_EQ(j["opaque"], std::vector<double>{0.05});
  EXPECT_EQ(j["tolerance_mm"], std::vector<double>{2.0});
  EXPECT_EQ(j["u_ind"], std::vector<double>{1.0});
  EXPECT_EQ(j["blob_rel"], std::vector<double>{0.2});
  EXPECT_EQ(j["blob_threshold"], std::vector<double>{0.2});
  EXPECT_EQ(j["mass_precision"], std::vector<double>{1.0});
  EXPECT_EQ(j["f1"], std::vector<double>{1.0});
  EXPECT_EQ(j["blobs6"], std::vector<double>{0.0});
  EXPECT_EQ(j["components6"], std::vector<double>{1.0});
  EXPECT_NEAR(j["surface_peak"].at(0), m.surface_peak, 1e-8);
  EXPECT_NEAR(j["shell_thickness_mm"].at(0), m.shell_thickness_mm, 1e-8);
  EXPECT_EQ(j["thickness_points"], std::vector<double>{double(m.thickness_points)});
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
  // The new options: the tolerance in mm (here 1 mm voxels), u_ind, the relative blob threshold.
  const test::RunResult n = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json", "--tolerance-mm", "1.5",
                                 "--tolerance", "7", "--u-ind", "0.5", "--blob-rel", "0.6", "--opaque", "0.01"});
  ASSERT_EQ(n.status, 0) << n.err;
  ASSERT_NO_THROW(j = parse_flat_json(n.out)) << n.out;
  p = {};
  p.tolerance_mm = 1.5;
  p.u_ind = 0.5;
  p.blob_rel = 0.6;
  p.opaque = 0.01;
  const Metrics mn = evaluate_opacity(shell(sdf), sdf, p);
  EXPECT_EQ(j["tolerance"], std::vector<double>{1.5}) << "--tolerance-mm overrides --tolerance";
  EXPECT_EQ(j["tolerance_mm"], std::vector<double>{1.5});
  EXPECT_EQ(j["blob_threshold"], std::vector<double>{0.6});
  EXPECT_NEAR(j["surface_peak"].at(0), mn.surface_peak, 1e-8);
  EXPECT_NEAR(j["surface_peak"].at(0), 2 * m.surface_peak, 1e-8);
  EXPECT_NEAR(j["mass_precision"].at(0), mn.mass_precision, 1e-8);
  EXPECT_NEAR(j["percent_opaque"].at(0), mn.percent_opaque, 1e-8);
  EXPECT_GT(mn.percent_opaque, m.percent_opaque);
}

TEST_F(CliEvaluate, RecallVisibleFromTheShadowBesideTheTruthOrGiven) {
  const Volume sdf = sphere_sdf();
  write_volume(file("truth_sdf.nrrd"), sdf);
  write_volume(file("u.nrrd"), shell(sdf));
  // No shadow volume: the key is there, null.
  std::map<std::string, std::vector<double>> j;
  test::RunResult r = run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd"), "--json"});
  ASSERT_EQ(r.status, 0) << r.err;
  ASSERT_NO_THROW(j = parse_flat_json(r.out)) << r.out;
  ASSERT_EQ(j.count("recall_visible"), 1u) << r.out;
  EXPECT_TRUE(std::isnan(j["recall_visible"].at(0))) << r.out;
  // shadow_db.nrrd beside the truth, as `softshell phantom` writes it, is found.
  const Volume shadow = half_shadow(sdf, 30.0f);
  write_volume(file("shadow_db.nrrd"), shadow);
  MetricsParams p;
  p.shadow_db = &shadow;
  const Metrics m = evaluate_opacity(shell(sdf), sdf, p);
  r = run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd"), "--json"});
  ASSERT_EQ(r.status, 0) << r.err;
  ASSERT_NO_THROW(j = parse_flat_json(r.out)) << r.out;
  EXPECT_EQ(j["recall_visible"], std::vector<double>{1.0});
  EXPECT_EQ(j["visible_surface_voxels"], std::vector<double>{double(m.visible_surface_voxels)});
  EXPECT_EQ(j["visible_db"], std::vector<double>{20.0});
  EXPECT_EQ(j["recall"], std::vector<double>{1.0});
  EXPECT_NEAR(j["f1_visible"].at(0), m.f1_visible, 1e-9);
  EXPECT_NEAR(j["surface_peak_visible"].at(0), m.surface_peak_visible, 1e-9);
  // --shadow none turns it off; --shadow FILE and --visible-db are used.
  r = run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd"), "--json", "--shadow", "none"});
  ASSERT_NO_THROW(j = parse_flat_json(r.out)) << r.out;
  EXPECT_TRUE(std::isnan(j["recall_visible"].at(0)));
  EXPECT_TRUE(std::isnan(j["f1_visible"].at(0)));
  EXPECT_TRUE(std::isnan(j["surface_peak_visible"].at(0)));
  write_volume(file("other.nrrd"), half_shadow(sdf, 50.0f));
  r = run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd"), "--json", "--shadow", file("other.nrrd"),
           "--visible-db", "60"});
  ASSERT_EQ(r.status, 0) << r.err;
  ASSERT_NO_THROW(j = parse_flat_json(r.out)) << r.out;
  EXPECT_EQ(j["visible_surface_voxels"], std::vector<double>{double(m.facing_surface_voxels)});
  // The table names it; a shadow of other dims is a one-line error.
  r = run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd")});
  EXPECT_NE(r.out.find("recall_visible"), std::string::npos) << r.out;
  write_volume(file("bad.nrrd"), sphere_sdf(16, 8, 5));
  expect_one_line_error(run({"evaluate", file("u.nrrd"), file("truth_sdf.nrrd"), "--shadow", file("bad.nrrd")}),
                        {"dims differ", "bad.nrrd"});
}

TEST_F(CliEvaluate, TableNamesEveryMetric) {
  const Volume sdf = sphere_sdf(24, 12, 7);
  write_volume(file("truth.nrrd"), sdf);
  write_volume(file("u.mha"), shell(sdf));
  const test::RunResult r = run({"evaluate", file("u.mha"), file("truth.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  for (const char* word : {"precision", "recall", "spurious_blobs", "components", "normal_error_deg",
                           "percent_opaque", "splats", "facing_surface_voxels", "24x24x24", "1.0000",
                           "mass_precision", "f1_mass", "surface_peak", "shell_thickness_mm", "blobs6",
                           "blob6_voxel_share", "components6", "u > 0.050", "f1_visible", "surface_peak_visible"})
    EXPECT_NE(r.out.find(word), std::string::npos) << word << " not in:\n" << r.out;
}

TEST_F(CliEvaluate, OrientationByTheDataReadsTheBmodeVolume) {
  // --orientation data --volume V scores the tensor of V's orientation field
  // (host/orientation.hpp), the splats `render --orientation data` draws.
  const Volume sdf = sphere_sdf(24, 12, 7);
  Volume u = smooth_shell(sdf, 1.5), bmode = sdf;
  std::mt19937_64 rng(test::seed());
  std::uniform_real_distribution<double> amp(0.3, 1.0);
  for (float& f : u.data) f = float(f * amp(rng));
  for (float& f : bmode.data) f = float(std::clamp(100.0 - 30.0 * f, 0.0, 255.0));
  write_volume(file("truth.nrrd"), sdf);
  write_volume(file("u.nrrd"), u);
  write_volume(file("bmode.nrrd"), bmode);
  const test::RunResult r = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json", "--orientation", "data",
                                 "--volume", file("bmode.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  std::map<std::string, std::string> strings;
  std::map<std::string, std::vector<double>> j;
  ASSERT_NO_THROW(j = parse_flat_json(r.out, &strings)) << r.out;
  EXPECT_EQ(strings["orientation"], "data");
  const Volume field = data_orientation_field(read_volume(file("bmode.nrrd")));
  MetricsParams p;
  p.orientation_field = &field;
  EXPECT_NEAR(j["normal_error_deg"].at(0), evaluate_opacity(read_volume(file("u.nrrd")), sdf, p).normal_error_deg, 1e-9);
  const test::RunResult t = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json"});
  ASSERT_EQ(t.status, 0) << t.err;
  strings.clear();
  ASSERT_NO_THROW(j = parse_flat_json(t.out, &strings)) << t.out;
  EXPECT_EQ(strings["orientation"], "tensor");
  const test::RunResult g = run({"evaluate", file("u.nrrd"), file("truth.nrrd"), "--json", "--orientation", "gradient"});
  ASSERT_EQ(g.status, 0) << g.err;
  strings.clear();
  ASSERT_NO_THROW(j = parse_flat_json(g.out, &strings)) << g.out;
  EXPECT_EQ(strings["orientation"], "gradient");
  EXPECT_EQ(j["tensor_sigma"], std::vector<double>{0.0});
  // The B-mode volume is needed, read only for data, and must match u.
  const std::string uu = file("u.nrrd"), tt = file("truth.nrrd");
  expect_one_line_error(run({"evaluate", uu, tt, "--orientation", "data"}), {"--orientation data", "--volume"});
  expect_one_line_error(run({"evaluate", uu, tt, "--volume", file("bmode.nrrd")}), {"--volume", "--orientation data"});
  expect_one_line_error(run({"evaluate", uu, tt, "--orientation", "sideways"}), {"--orientation"});
  expect_one_line_error(run({"evaluate", uu, tt, "--orientation", "data", "--volume", file("gone.nrrd")}),
                        {"gone.nrrd"});
  write_volume(file("small.nrrd"), sphere_sdf(16, 8, 5));
  expect_one_line_error(run({"evaluate", uu, tt, "--orientation", "data", "--volume", file("small.nrrd")}),
                        {"dims differ", "small.nrrd"});
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
  for (const char* bad : {"0", "-1", "inf", "nan"}) {
    SCOPED_TRACE(bad);
    expect_one_line_error(run({"evaluate", t, t, "--u-ind", bad}), {"--u-ind"});
    expect_one_line_error(run({"evaluate", t, t, "--tolerance-mm", bad}), {"--tolerance-mm"});
  }
  for (const char* bad : {"0", "-0.5", "1.5", "nan"}) {
    SCOPED_TRACE(bad);
    expect_one_line_error(run({"evaluate", t, t, "--blob-rel", bad}), {"--blob-rel"});
  }
  expect_one_line_error(run({"evaluate", t}), {"TRUTH_SDF"});
}

}  // namespace
}  // namespace softshell
