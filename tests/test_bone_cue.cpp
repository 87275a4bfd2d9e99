// The bone cue (host/bone_cue.hpp): the score and the weight against a
// brute-force reference written independently here (a direct 3D Gaussian,
// direct window and box means), the score's
// behaviour on a synthetic echo over a shadow, the automatic rule, and the
// classifier's densities with an edge weight.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "bone_cue.hpp"
#include "test_support.hpp"
#include "variational.hpp"

namespace softshell {
namespace {

// Direct (non-separable) Gaussian, border clamped, radius ceil(3 sigma) per axis.
std::vector<double> ref_gaussian(const Volume& v, double sigma_mm) {
  const long n[3] = {long(v.dims[0]), long(v.dims[1]), long(v.dims[2])};
  long r[3];
  std::vector<double> w[3];
  for (int a = 0; a < 3; ++a) {
    const double s = sigma_mm / v.spacing[a];
    r[a] = std::min<long>(long(std::ceil(3 * s)), n[a] - 1);
    double sum = 0;
    for (long k = -r[a]; k <= r[a]; ++k) w[a].push_back(std::exp(-0.5 * double(k * k) / (s * s))), sum += w[a].back();
    for (double& x : w[a]) x /= sum;
  }
  std::vector<double> out(v.voxels());
  for (long z = 0; z < n[2]; ++z)
    for (long y = 0; y < n[1]; ++y)
      for (long x = 0; x < n[0]; ++x) {
        double acc = 0;
        for (long c = -r[2]; c <= r[2]; ++c)
          for (long b = -r[1]; b <= r[1]; ++b)
            for (long a = -r[0]; a <= r[0]; ++a) {
              const long xx = std::clamp(x + a, 0L, n[0] - 1), yy = std::clamp(y + b, 0L, n[1] - 1),
                         zz = std::clamp(z + c, 0L, n[2] - 1);
              acc += w[0][std::size_t(a + r[0])] * w[1][std::size_t(b + r[1])] * w[2][std::size_t(c + r[2])] *
                     v.at(std::size_t(xx), std::size_t(yy), std::size_t(zz));
            }
        out[v.index(std::size_t(x), std::size_t(y), std::size_t(z))] = acc;
      }
  return out;
}

double ref_quantile(std::vector<double> s, double q) {
  std::sort(s.begin(), s.end());
  return s[std::min(s.size() - 1, std::size_t(q * double(s.size() - 1) + 0.5))];
}

// The score of docs/numerics.md "The bone cue", beam along +z; `mask`
// (optional, 1 = scanned) as bone_cue_score takes it.
std::vector<double> ref_score(const Volume& v, const BoneCueParams& p, const std::vector<std::uint8_t>* mask = nullptr) {
  const std::vector<double> vs = ref_gaussian(v, p.sigma_mm);
  const auto in = [&](std::size_t i) { return !mask || (*mask)[i] != 0; };
  std::vector<double> scanned;
  for (std::size_t i = 0; i < vs.size(); ++i)
    if (in(i)) scanned.push_back(vs[i]);
  const double spread = ref_quantile(scanned, 0.9) - ref_quantile(scanned, 0.1);
  const std::size_t nx = v.dims[0], ny = v.dims[1], nz = v.dims[2];
  // the surroundings: the mean over the scanned voxels of the square of
  // half-width lateral_mm across the beam, same z
  const long rx = std::max(1L, std::lround(p.lateral_mm / v.spacing[0]));
  const long ry = std::max(1L, std::lround(p.lateral_mm / v.spacing[1]));
  auto around = [&](std::size_t x, std::size_t y, std::size_t z) {
    double sum = 0;
    long c = 0;
    for (long yy = std::max(0L, long(y) - ry); yy <= std::min(long(ny) - 1, long(y) + ry); ++yy)
      for (long xx = std::max(0L, long(x) - rx); xx <= std::min(long(nx) - 1, long(x) + rx); ++xx) {
        const std::size_t i = v.index(std::size_t(xx), std::size_t(yy), z);
        if (in(i)) sum += vs[i], ++c;
      }
    return c ? sum / double(c) : 0.0;
  };
  const long k0 = std::max(1L, std::lround(p.below_from_mm / v.spacing[2]));
  const long k1 = std::max(k0, std::lround(p.below_to_mm / v.spacing[2]));
  std::vector<double> out(v.voxels(), 0.0);
  for (std::size_t z = 0; z < nz; ++z)
    for (std::size_t y = 0; y < ny; ++y)
      for (std::size_t x = 0; x < nx; ++x) {
        if (!in(v.index(x, y, z))) continue;
        double sum = 0;
        long c = 0;
        for (long k = k0; k <= k1; ++k)
          if (long(z) + k < long(nz) && in(v.index(x, y, std::size_t(long(z) + k))))
            sum += vs[v.index(x, y, std::size_t(long(z) + k))], ++c;
        if (2 * c < k1 - k0 + 1) continue;
        const double here = vs[v.index(x, y, z)];
        double s = here - sum / double(c);
        if (p.depth_term) s = std::min(s, here - around(x, y, z));
        out[v.index(x, y, z)] = s / spread;
      }
  return out;
}

// Muscle-like speckle (mean 120), a bright plate (a bone echo, 250) at
// z = 9..12 (2 mm) over x, y in [6, 18), an acoustic shadow (30) beneath it
// down to the bottom, and a bright layer over the whole plane at z = 2..4 (a
// near field: bright, but so is its whole depth).
Volume bone_scene(std::uint64_t seed) {
  Volume v({24, 24, 32}, {0.5, 0.5, 0.5}, ScalarType::UInt8);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> noise(-40.0f, 40.0f);
  for (std::size_t z = 0; z < 32; ++z)
    for (std::size_t y = 0; y < 24; ++y)
      for (std::size_t x = 0; x < 24; ++x) {
        const bool under = x >= 6 && x < 18 && y >= 6 && y < 18;
        float g = 120.0f + noise(rng);
        if (z >= 2 && z <= 4) g = 240.0f;
        if (under && z >= 9 && z <= 12) g = 250.0f;
        if (under && z > 12) g = 30.0f + 0.2f * noise(rng);
        v.at(x, y, z) = g;
      }
  return v;
}

TEST(BoneCue, ScoreMatchesABruteForceReference) {
  const Volume v = bone_scene(test::seed());
  for (const bool depth : {true, false}) {
    BoneCueParams p;
    p.depth_term = depth;
    const std::vector<float> s = bone_cue_score(v, nullptr, p);
    const std::vector<double> r = ref_score(v, p);
    ASSERT_EQ(s.size(), r.size());
    double worst = 0;
    for (std::size_t i = 0; i < s.size(); ++i) worst = std::max(worst, std::abs(double(s[i]) - r[i]));
    EXPECT_LT(worst, 1e-4) << "depth term " << depth;
    // Thread count does not change the result.
    p.threads = 1;
    EXPECT_EQ(bone_cue_score(v, nullptr, p), s);
  }
  // With a mask: a fan-like footprint (the first rows unscanned, more of
  // them toward the sides) and an unscanned block inside.
  std::vector<std::uint8_t> mask(v.voxels(), 1);
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x) {
        const long edge = std::labs(long(x) - 12) / 3;
        if (long(z) < edge || (x >= 18 && y >= 18 && z >= 20 && z < 26)) mask[v.index(x, y, z)] = 0;
      }
  BoneCueParams p;
  const std::vector<float> s = bone_cue_score(v, &mask, p);
  const std::vector<double> r = ref_score(v, p, &mask);
  double worst = 0;
  for (std::size_t i = 0; i < s.size(); ++i) worst = std::max(worst, std::abs(double(s[i]) - r[i]));
  EXPECT_LT(worst, 1e-4) << "masked";
}

TEST(BoneCue, WeightIsTheSmoothStepReachingUpTheBeam) {
  const Volume v = bone_scene(test::seed() + 1);
  BoneCueParams p;
  const std::vector<float> s = bone_cue_score(v, nullptr, p);
  const std::vector<float> w = bone_cue_weight(v, s, p);
  const long reach = std::lround(p.reach_mm / v.spacing[2]);
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < v.dims[0]; ++x) {
        double m = 0;
        for (long k = 0; k <= reach && long(z) + k < long(v.dims[2]); ++k) {
          const double t = std::clamp((s[v.index(x, y, std::size_t(long(z) + k))] - p.score_lo) /
                                          (p.score_hi - p.score_lo), 0.0, 1.0);
          m = std::max(m, p.floor + (1 - p.floor) * t * t * (3 - 2 * t));
        }
        ASSERT_NEAR(w[v.index(x, y, z)], m, 1e-6) << x << ' ' << y << ' ' << z;
      }
}

TEST(BoneCue, AnEchoOverAShadowScoresAndNothingElseDoes) {
  const Volume v = bone_scene(test::seed() + 2);
  BoneCueParams p;
  const std::vector<float> w = bone_cue_weight(v, bone_cue_score(v, nullptr, p), p);
  // The plate and the voxel just above it (its front flank): full weight.
  EXPECT_GT(w[v.index(12, 12, 10)], 0.99f);
  EXPECT_GT(w[v.index(12, 12, 8)], 0.99f);
  // The near-field layer (bright over the whole plane), the shadow's walls
  // (muscle beside the dark column, well below the plate) and the muscle
  // far from the plate: no weight.
  EXPECT_LT(w[v.index(2, 2, 3)], 0.01f);
  EXPECT_LT(w[v.index(21, 12, 3)], 0.01f);
  EXPECT_LT(w[v.index(5, 12, 22)], 0.01f);
  EXPECT_LT(w[v.index(18, 12, 22)], 0.01f);
  EXPECT_LT(w[v.index(12, 12, 22)], 0.01f);
  std::size_t heavy = 0;
  for (std::size_t y = 0; y < 24; ++y)
    for (std::size_t x = 0; x < 24; ++x)
      for (std::size_t z = 15; z < 32; ++z) heavy += w[v.index(x, y, z)] > 0.5f;
  EXPECT_EQ(heavy, 0u) << "nothing below the plate is bone-like";
}

TEST(BoneCue, TheAutomaticRuleTellsEchoesOverShadowsFromFluidOverTissue) {
  BoneCueParams p;
  BoneCueReport r;
  EXPECT_TRUE(bone_cue_auto(bone_scene(test::seed() + 3), nullptr, p, &r));
  EXPECT_GT(r.falling_share, r.rising_share);
  EXPECT_GT(r.edge_voxels, 0u);
  // Dark fluid over a bright tissue block (a face): the strong edges rise.
  Volume face({24, 24, 32}, {0.5, 0.5, 0.5}, ScalarType::UInt8);
  std::mt19937_64 rng(test::seed() + 4);
  std::uniform_real_distribution<float> noise(-10.0f, 10.0f);
  for (std::size_t z = 0; z < 32; ++z)
    for (std::size_t y = 0; y < 24; ++y)
      for (std::size_t x = 0; x < 24; ++x) face.at(x, y, z) = (z >= 14 ? 170.0f : 20.0f) + noise(rng);
  EXPECT_FALSE(bone_cue_auto(face, nullptr, p, &r));
  EXPECT_GT(r.rising_share, r.falling_share);
  // The modes: off gives no weights, on always does, auto as the rule says.
  EXPECT_FALSE(bone_cue_weights(face, nullptr, BoneCueMode::Off, p));
  EXPECT_FALSE(bone_cue_weights(face, nullptr, BoneCueMode::Auto, p));
  EXPECT_TRUE(bone_cue_weights(face, nullptr, BoneCueMode::On, p));
  EXPECT_TRUE(bone_cue_weights(bone_scene(test::seed() + 3), nullptr, BoneCueMode::Auto, p));
  BoneCueMode m;
  EXPECT_TRUE(parse_bone_cue_mode("auto", m));
  EXPECT_EQ(m, BoneCueMode::Auto);
  EXPECT_FALSE(parse_bone_cue_mode("yes", m));
}

// The classifier's densities with an edge weight: where w = 0 the edge is
// gone (c = delta: rho = gamma delta u_ind), where w = 1 the densities are
// those of the same system without a weight at the same reference gradient.
TEST(BoneCue, EdgeWeightReachesTheDensities) {
  const Volume v = bone_scene(test::seed() + 5);
  VariationalParams p;
  p.v_iso = 0.7;
  auto w = std::make_shared<std::vector<float>>(v.voxels(), 1.0f);
  for (std::size_t z = 0; z < v.dims[2]; ++z)
    for (std::size_t y = 0; y < v.dims[1]; ++y)
      for (std::size_t x = 0; x < 12; ++x) (*w)[v.index(x, y, z)] = 0.0f;
  VariationalParams pw = p;
  pw.edge_weight = w;
  const Volume vn = v.with_data([&] {
    std::vector<float> d = v.data;
    for (float& f : d) f /= 255.0f;
    return d;
  }(), ScalarType::Float32);
  const DeviceSystem with(test::runtime(), vn, pw);
  VariationalParams pg = p;
  pg.g_ref = with.resolved().g_ref;
  const DeviceSystem without(test::runtime(), vn, pg);
  const Densities a = with.download_densities(), b = without.download_densities();
  std::size_t checked_zero = 0, checked_one = 0;
  for (std::size_t i = 0; i < a.mu.size(); ++i) {
    if (a.fixed[i]) continue;
    if ((*w)[i] == 0.0f) {
      EXPECT_NEAR(a.rho[i], p.gamma * p.delta * p.u_ind, 1e-7);
      EXPECT_LE(a.mu[i], b.mu[i] * (1 + 1e-6) + p.alpha * p.weight_cap);
      ++checked_zero;
    } else {
      EXPECT_FLOAT_EQ(a.mu[i], b.mu[i]);
      EXPECT_FLOAT_EQ(a.rho[i], b.rho[i]);
      ++checked_one;
    }
  }
  EXPECT_GT(checked_zero, 1000u);
  EXPECT_GT(checked_one, 1000u);
  // The tangential tensor does not depend on |grad v|.
  for (int k = 0; k < 6; ++k) EXPECT_EQ(a.T[k], b.T[k]);
  // A weight of the wrong size is refused.
  pw.edge_weight = std::make_shared<std::vector<float>>(7, 1.0f);
  EXPECT_THROW(DeviceSystem(test::runtime(), vn, pw), std::invalid_argument);
}

}  // namespace
}  // namespace softshell
