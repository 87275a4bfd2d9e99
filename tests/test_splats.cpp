// Splat generation (kernels/splat.cl, host/splats.*) against a float64 CPU
// reference written here from the paper's definitions: which voxels get a
// splat, their centres (mm, spacing and origin honoured), alphas, normals
// (central-difference grad u per mm), triangle geometry, and the three
// midway normals (trilinear interpolation of the gradient field).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <numeric>

#include "error.hpp"
#include "orientation.hpp"
#include "splats.hpp"
#include "test_support.hpp"

namespace softshell::test {
namespace {

using V3 = std::array<double, 3>;

double dot(const V3& a, const V3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
double norm(const V3& a) { return std::sqrt(dot(a, a)); }

// grad u per mm at a voxel: central inside, one-sided at the ends, 0 on a
// one-sample axis (the rule of kernels/gradient.cl).
V3 ref_gradient(const Volume& u, long x, long y, long z) {
  V3 g{};
  const long n[3] = {long(u.dims[0]), long(u.dims[1]), long(u.dims[2])};
  const long c[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    if (n[a] < 2) continue;
    auto at = [&](long k) {
      long p[3] = {x, y, z};
      p[a] = k;
      return double(u.at(p[0], p[1], p[2]));
    };
    const long lo = std::max(c[a] - 1, 0L), hi = std::min(c[a] + 1, n[a] - 1);
    g[a] = (at(hi) - at(lo)) / (double(hi - lo) * u.spacing[a]);
  }
  return g;
}

// Trilinear interpolation of the gradient field at p (voxel coordinates).
V3 ref_gradient_at(const Volume& u, V3 p) {
  long i0[3], i1[3];
  double w[3];
  for (int a = 0; a < 3; ++a) {
    p[a] = std::clamp(p[a], 0.0, double(u.dims[a] - 1));
    i0[a] = long(std::floor(p[a]));
    i1[a] = std::min(i0[a] + 1, long(u.dims[a]) - 1);
    w[a] = p[a] - double(i0[a]);
  }
  V3 g{};
  for (int corner = 0; corner < 8; ++corner) {
    const long x = corner & 1 ? i1[0] : i0[0], y = corner & 2 ? i1[1] : i0[1], z = corner & 4 ? i1[2] : i0[2];
    const double wt = (corner & 1 ? w[0] : 1 - w[0]) * (corner & 2 ? w[1] : 1 - w[1]) * (corner & 4 ? w[2] : 1 - w[2]);
    const V3 gc = ref_gradient(u, x, y, z);
    for (int a = 0; a < 3; ++a) g[a] += wt * gc[a];
  }
  return g;
}

V3 v3(const float* f) { return {f[0], f[1], f[2]}; }

// Checks every splat of `set` against the reference on `u`.
void check_against_reference(const Volume& u, const SplatSet& set, float threshold) {
  const double a = std::sqrt(1.0 / (-0.25 * std::log(double(threshold))));
  EXPECT_NEAR(set.a, a, 1e-12);
  std::size_t k = 0, flat = 0;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        if (!(u.at(x, y, z) > threshold)) continue;
        ASSERT_LT(k, set.splats.size()) << "too few splats; voxel (" << x << ", " << y << ", " << z << ")";
        const Splat& s = set.splats[k++];
        SCOPED_TRACE("splat " + std::to_string(k - 1) + " at voxel (" + std::to_string(x) + ", " +
                     std::to_string(y) + ", " + std::to_string(z) + ")");
        const V3 centre{u.origin[0] + u.spacing[0] * x, u.origin[1] + u.spacing[1] * y, u.origin[2] + u.spacing[2] * z};
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(s.centre[c], centre[c], 1e-5 * (1 + std::abs(centre[c])));
        ASSERT_EQ(s.alpha, u.at(x, y, z));
        const V3 g = ref_gradient(u, long(x), long(y), long(z));
        const double gn = norm(g);
        ASSERT_NEAR(s.strength, gn, 1e-5 * (1 + gn));
        if (gn < 1e-3) {  // direction ill-defined in float32
          ++flat;
          continue;
        }
        const V3 n = v3(s.normal);
        ASSERT_NEAR(norm(n), 1.0, 1e-5);
        for (int c = 0; c < 3; ++c) ASSERT_NEAR(n[c], g[c] / gn, 2e-4);
        // S and T: in the plane perpendicular to the mm-space normal; mapped
        // back to voxel coordinates they are orthogonal with length a.
        const V3 S = v3(s.s), T = v3(s.t);
        ASSERT_NEAR(dot(S, n), 0.0, 1e-4 * norm(S));
        ASSERT_NEAR(dot(T, n), 0.0, 1e-4 * norm(T));
        const V3 Sv{S[0] / u.spacing[0], S[1] / u.spacing[1], S[2] / u.spacing[2]};
        const V3 Tv{T[0] / u.spacing[0], T[1] / u.spacing[1], T[2] / u.spacing[2]};
        ASSERT_NEAR(norm(Sv), a, 1e-5);
        ASSERT_NEAR(norm(Tv), a, 1e-5);
        ASSERT_NEAR(dot(Sv, Tv), 0.0, 1e-5);
        // Three normals, midway between the centre and each vertex.
        const double corner[3][2] = {{1, 0}, {-0.5, -0.5 * std::sqrt(3.0)}, {-0.5, 0.5 * std::sqrt(3.0)}};
        for (int c = 0; c < 3; ++c) {
          const V3 q{x + 0.5 * (corner[c][0] * Sv[0] + corner[c][1] * Tv[0]),
                     y + 0.5 * (corner[c][0] * Sv[1] + corner[c][1] * Tv[1]),
                     z + 0.5 * (corner[c][0] * Sv[2] + corner[c][1] * Tv[2])};
          V3 m = ref_gradient_at(u, q);
          const double mn = norm(m);
          if (mn < 1e-3 || std::abs(dot(m, n)) < 1e-3 * mn) continue;  // sign ill-defined
          const double sign = dot(m, n) < 0 ? -1.0 : 1.0;
          for (int i = 0; i < 3; ++i)
            ASSERT_NEAR(s.vertex_normal[c][i], sign * m[i] / mn, 5e-4) << "vertex normal " << c;
        }
      }
  EXPECT_EQ(k, set.splats.size()) << "too many splats";
  EXPECT_LT(flat, set.splats.size() / 10 + 1);
}

TEST(Splats, MatchCpuReferenceOnOddAnisotropicVolumes) {
  Runtime& rt = runtime();
  const std::vector<std::pair<Dims3, Vec3d>> cases = {
      {{13, 9, 7}, {0.7, 1.3, 2.0}}, {{5, 7, 3}, {1.0, 1.0, 1.0}}, {{17, 1, 11}, {0.5, 0.9, 1.7}}};
  std::uint64_t k = 0;
  for (const auto& [dims, spacing] : cases) {
    SCOPED_TRACE("dims " + std::to_string(dims[0]) + "x" + std::to_string(dims[1]) + "x" + std::to_string(dims[2]));
    Volume u = random_volume(dims, spacing, seed() + k++);
    u.origin = {-3.25, 5.5, 1.5};
    for (float threshold : {0.2f, 0.55f}) {
      SplatParams p;
      p.threshold = threshold;
      p.normals = SplatNormals::Gradient;
      p.centres = SplatCentres::Voxel;  // the paper's placement; shell centres: ShellCentresMatchTheReference
      const SplatSet set = generate_splats(rt, u, p);
      const std::size_t want = std::count_if(u.data.begin(), u.data.end(), [&](float v) { return v > threshold; });
      ASSERT_EQ(set.splats.size(), want);
      check_against_reference(u, set, threshold);
      if (HasFatalFailure()) return;
    }
  }
}

// Every splat normal and the three midway normals of `set` (made from u with
// SplatCentres::Voxel) against host/orientation.cpp's float64 structure
// tensor of `field` (u itself, or the data orientation field).
void expect_tensor_normals(const SplatSet& set, const Volume& u, const Volume& field, const SplatParams& p) {
  auto check = [&](const V3& want, const float* got, double tol_deg, const char* what) {
    const double wn = norm(want);
    ASSERT_GT(wn, 0);
    const V3 g = v3(got);
    const double c = dot(want, g) / (wn * norm(g));
    EXPECT_GT(c, std::cos(tol_deg * 3.14159265358979 / 180)) << what;
  };
  std::size_t k = 0;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        if (!(u.at(x, y, z) > p.threshold)) continue;
        ASSERT_LT(k, set.splats.size());
        const Splat& s = set.splats[k++];
        const auto t = tensor_orientation_reference(field, {double(x), double(y), double(z)}, p.tensor_sigma);
        const V3 tv{t[0], t[1], t[2]};
        ASSERT_NEAR(s.strength, norm(tv), 1e-3 * norm(tv));
        check(tv, s.normal, 0.5, "centre normal");
        const V3 S = v3(s.s), T = v3(s.t);
        const V3 Sv{S[0] / u.spacing[0], S[1] / u.spacing[1], S[2] / u.spacing[2]};
        const V3 Tv{T[0] / u.spacing[0], T[1] / u.spacing[1], T[2] / u.spacing[2]};
        const double corner[3][2] = {{1, 0}, {-0.5, -0.5 * std::sqrt(3.0)}, {-0.5, 0.5 * std::sqrt(3.0)}};
        for (int c = 0; c < 3; ++c) {
          const std::array<double, 3> q{x + 0.5 * (corner[c][0] * Sv[0] + corner[c][1] * Tv[0]),
                                        y + 0.5 * (corner[c][0] * Sv[1] + corner[c][1] * Tv[1]),
                                        z + 0.5 * (corner[c][0] * Sv[2] + corner[c][1] * Tv[2])};
          const auto m = tensor_orientation_reference(field, q, p.tensor_sigma);
          V3 mv{m[0], m[1], m[2]};
          if (dot(mv, v3(s.normal)) < 0) mv = {-m[0], -m[1], -m[2]};  // sign-aligned with the centre
          check(mv, s.vertex_normal[c], 0.5, "vertex normal");
        }
      }
  EXPECT_EQ(k, set.splats.size());
}

TEST(Splats, TensorOrientationMatchesTheReference) {
  // The default orientation: the structure tensor of u.
  Runtime& rt = runtime();
  Volume u = random_volume({15, 11, 9}, {0.7, 1.3, 1.0}, seed() + 11);
  u.origin = {1.0, -2.0, 0.5};
  SplatParams p;
  ASSERT_EQ(p.normals, SplatNormals::Tensor) << "the tensor is the default";
  p.centres = SplatCentres::Voxel;  // normals at the voxel centres the reference evaluates
  p.tensor_sigma = 1.2;
  const SplatSet set = generate_splats(rt, u, p);
  ASSERT_GT(set.splats.size(), 100u);
  expect_tensor_normals(set, u, u, p);
}

TEST(Splats, DataOrientationMatchesTheReference) {
  // --orientation data: the same tensor of the B-mode volume's orientation
  // field (a voxel's lowpass), an unrelated random field here, while the
  // splats themselves (which voxels, alpha, centres) still come from u.
  Runtime& rt = runtime();
  Volume u = random_volume({15, 11, 9}, {0.7, 1.3, 1.0}, seed() + 11);
  u.origin = {1.0, -2.0, 0.5};
  Volume bmode = random_volume(u.dims, u.spacing, seed() + 12);
  for (float& f : bmode.data) f *= 255.0f;  // B-mode units: the orientation does not care
  SplatParams p;
  p.normals = SplatNormals::Data;
  p.centres = SplatCentres::Voxel;
  p.tensor_sigma = 1.2;
  const SplatSet set = generate_splats(rt, u, p, nullptr, &bmode);
  SplatParams by_u = p;
  by_u.normals = SplatNormals::Tensor;
  const SplatSet tensor = generate_splats(rt, u, by_u);
  ASSERT_EQ(set.splats.size(), tensor.splats.size());
  for (std::size_t i = 0; i < set.splats.size(); ++i) {
    ASSERT_EQ(set.splats[i].alpha, tensor.splats[i].alpha);
    for (int a = 0; a < 3; ++a) ASSERT_EQ(set.splats[i].centre[a], tensor.splats[i].centre[a]);
  }
  expect_tensor_normals(set, u, data_orientation_field(bmode), p);
  // Without the B-mode volume, or with one of other dims: an input error, no splats.
  EXPECT_THROW(generate_splats(rt, u, p), InputError);
  const Volume other = random_volume({15, 11, 8}, u.spacing, seed() + 13);
  EXPECT_THROW(generate_splats(rt, u, p, nullptr, &other), InputError);
}

TEST(Splats, SmoothFieldNormalsAreRadial) {
  // u = a soft shell around a centre: every normal must point along the
  // radius (in mm space, with anisotropic spacing), outside the shell's ridge.
  Runtime& rt = runtime();
  Volume u({21, 17, 13}, {0.8, 1.0, 1.3});
  const V3 c{8.0, 8.0, 7.8};
  for (std::size_t z = 0; z < 13; ++z)
    for (std::size_t y = 0; y < 17; ++y)
      for (std::size_t x = 0; x < 21; ++x) {
        const double r = norm({x * 0.8 - c[0], y * 1.0 - c[1], z * 1.3 - c[2]});
        u.at(x, y, z) = float(std::max(0.0, 1.0 - std::abs(r - 5.0) / 2.5));
      }
  SplatParams gradient;
  gradient.normals = SplatNormals::Gradient;
  const SplatSet set = generate_splats(rt, u, gradient);
  ASSERT_GT(set.splats.size(), 100u);
  std::size_t checked = 0;
  for (const Splat& s : set.splats) {
    const V3 d{s.centre[0] - c[0], s.centre[1] - c[1], s.centre[2] - c[2]};
    const double r = norm(d);
    if (std::abs(r - 5.0) < 0.9 || std::abs(r - 5.0) > 1.6) continue;  // ridge and rim: one-sided mixes
    const double cosang = std::abs(dot(v3(s.normal), d)) / r;
    EXPECT_GT(cosang, 0.97) << "normal not radial at r = " << r;
    ++checked;
  }
  EXPECT_GT(checked, 50u);
  // The structure tensor (the default) is radial on the ridge too, where
  // the gradient of the tent's kink is not.
  const SplatSet tensor = generate_splats(rt, u);
  ASSERT_EQ(tensor.splats.size(), set.splats.size());
  std::size_t ridge = 0;
  for (const Splat& s : tensor.splats) {
    const V3 d{s.centre[0] - c[0], s.centre[1] - c[1], s.centre[2] - c[2]};
    const double r = norm(d);
    if (std::abs(r - 5.0) > 1.6) continue;
    EXPECT_GT(std::abs(dot(v3(s.normal), d)) / r, 0.97) << "tensor normal not radial at r = " << r;
    ridge += std::abs(r - 5.0) < 0.9;
  }
  EXPECT_GT(ridge, 50u);
}

TEST(Splats, DeterministicAndEmpty) {
  Runtime& rt = runtime();
  Volume u = random_volume({31, 19, 9}, {1.0, 0.6, 1.4}, seed() + 7);
  const SplatSet a = generate_splats(rt, u), b = generate_splats(rt, u);
  ASSERT_EQ(a.splats.size(), b.splats.size());
  EXPECT_EQ(std::memcmp(a.splats.data(), b.splats.data(), a.splats.size() * sizeof(Splat)), 0)
      << "two runs differ";
  Volume zero({9, 8, 7});
  SplatTiming t;
  EXPECT_TRUE(generate_splats(rt, zero, {}, &t).splats.empty());
  SplatParams bad;
  bad.threshold = 1.0f;
  EXPECT_THROW(generate_splats(rt, u, bad), std::invalid_argument);
}

TEST(Splats, GaussianParametersFollowThePaper) {
  // lambda = -0.25 ln(epsilon), a = sqrt(1 / lambda); the midway opacity of
  // two adjacent unit splats, 1 - (1 - G(half a voxel))^2, is about 0.95 for
  // any epsilon (half a voxel is 0.5 / a in texture units, so G = e^-0.25).
  for (double eps : {0.05, 0.2, 0.5})
    for (SplatGaussian kind : {SplatGaussian::Paper, SplatGaussian::Rim}) {
      const double lambda = splat_lambda(eps, kind), a = splat_size(eps, kind);
      EXPECT_NEAR(a * a * lambda, 1.0, 1e-12);
      const double r = 0.5 / a;
      const double g = std::exp(-r * r / lambda);
      EXPECT_NEAR(1 - (1 - g) * (1 - g), 0.951, 0.001);
      if (kind == SplatGaussian::Paper) {
        EXPECT_NEAR(lambda, -0.25 * std::log(eps), 1e-15);  // as printed
      } else {
        EXPECT_NEAR(std::exp(-0.25 / lambda), eps, 1e-12);  // G = eps on the circle of radius 0.5
      }
    }
  EXPECT_THROW(splat_lambda(0.0), std::invalid_argument);
  EXPECT_THROW(splat_lambda(1.0), std::invalid_argument);
}

TEST(Splats, ShellCentresMatchTheReference) {
  // SplatCentres::Shell (kernels/splat.cl): each centre moved along its unit
  // normal in voxel coordinates (here grad u, central differences per mm,
  // scaled by the spacing) to u's Gaussian-weighted mass centre within 3
  // voxels (sigma 1.5), at most one voxel; recomputed here in float64.
  Runtime& rt = runtime();
  Volume u = random_volume({13, 11, 9}, {0.7, 1.3, 1.1}, seed() + 11);
  u.origin = {2.5, -1.0, 4.0};
  SplatParams p;
  p.normals = SplatNormals::Gradient;
  ASSERT_EQ(p.centres, SplatCentres::Shell) << "shell centres are the default";
  const SplatSet set = generate_splats(rt, u, p);
  std::size_t k = 0, moved = 0;
  for (std::size_t z = 0; z < u.dims[2]; ++z)
    for (std::size_t y = 0; y < u.dims[1]; ++y)
      for (std::size_t x = 0; x < u.dims[0]; ++x) {
        if (!(u.at(x, y, z) > p.threshold)) continue;
        ASSERT_LT(k, set.splats.size());
        const Splat& s = set.splats[k++];
        const V3 g = ref_gradient(u, long(x), long(y), long(z));
        V3 nv{g[0] * u.spacing[0], g[1] * u.spacing[1], g[2] * u.spacing[2]};
        const double len = norm(nv);
        if (len < 1e-6) continue;  // a flat spot: the kernel's fallback direction
        for (double& c : nv) c /= len;
        double mass = 0, moment = 0;
        for (long dz = -3; dz <= 3; ++dz)
          for (long dy = -3; dy <= 3; ++dy)
            for (long dx = -3; dx <= 3; ++dx) {
              const long xx = long(x) + dx, yy = long(y) + dy, zz = long(z) + dz;
              if (xx < 0 || yy < 0 || zz < 0 || xx >= long(u.dims[0]) || yy >= long(u.dims[1]) || zz >= long(u.dims[2]))
                continue;
              const double v = u.at(std::size_t(xx), std::size_t(yy), std::size_t(zz));
              if (v <= 0) continue;
              const double w = v * std::exp(-double(dx * dx + dy * dy + dz * dz) / (2 * 1.5 * 1.5));
              mass += w;
              moment += w * (dx * nv[0] + dy * nv[1] + dz * nv[2]);
            }
        const double c = std::clamp(mass > 0 ? moment / mass : 0.0, -1.0, 1.0);
        moved += std::abs(c) > 0.05;
        const V3 want{u.origin[0] + u.spacing[0] * (double(x) + c * nv[0]),
                      u.origin[1] + u.spacing[1] * (double(y) + c * nv[1]),
                      u.origin[2] + u.spacing[2] * (double(z) + c * nv[2])};
        for (int a = 0; a < 3; ++a)
          ASSERT_NEAR(s.centre[a], want[a], 2e-4 * (1 + std::abs(want[a])))
              << "voxel (" << x << ", " << y << ", " << z << "), axis " << a << ", shift " << c;
      }
  EXPECT_EQ(k, set.splats.size());
  EXPECT_GT(moved, k / 4) << "too few centres moved for the test to mean anything";
}

TEST(Splats, BackToFrontOrders) {
  Runtime& rt = runtime();
  Volume u = random_volume({11, 10, 9}, {0.9, 1.1, 1.3}, seed() + 3);
  const SplatSet set = generate_splats(rt, u);
  ASSERT_FALSE(set.splats.empty());
  for (int axis = 0; axis < 3; ++axis)
    for (bool desc : {false, true}) {
      const auto order = axis_order(set, axis, desc);
      std::vector<std::uint32_t> sorted = order;
      std::sort(sorted.begin(), sorted.end());
      for (std::size_t i = 0; i < sorted.size(); ++i) ASSERT_EQ(sorted[i], i) << "not a permutation";
      // Monotone by voxel slab (the centre's nearest grid plane), voxel order within one.
      const auto slab = [&](std::uint32_t k) {
        return std::lround((set.splats[k].centre[axis] - set.origin[axis]) / set.spacing[axis]);
      };
      for (std::size_t i = 1; i < order.size(); ++i) {
        const long p = slab(order[i - 1]), q = slab(order[i]);
        ASSERT_TRUE(desc ? p >= q : p <= q) << "axis " << axis << " position " << i;
        if (p == q) ASSERT_LT(order[i - 1], order[i]) << "voxel order within a slab";
      }
    }
  EXPECT_EQ(axis_list_for_view({0.1, -0.2, 0.9}), 5);   // looking along +z: descending z
  EXPECT_EQ(axis_list_for_view({-0.8, 0.5, 0.1}), 0);  // along -x: ascending x
  std::vector<std::uint32_t> order;
  const std::array<double, 3> eye{40.0, -20.0, 5.0};
  depth_order(set, eye, order);
  ASSERT_EQ(order.size(), set.splats.size());
  auto dist = [&](std::uint32_t i) {
    const float* c = set.splats[i].centre;
    return norm({c[0] - eye[0], c[1] - eye[1], c[2] - eye[2]});
  };
  for (std::size_t i = 1; i < order.size(); ++i) ASSERT_GE(dist(order[i - 1]) + 1e-4, dist(order[i]));
}

}  // namespace
}  // namespace softshell::test
