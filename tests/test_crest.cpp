// Shells on a bright echo's crest (host/crest.hpp; docs/parameters.md, "The
// echo's crest"): on beam lines whose profile is written out by hand, the
// ramp's zero lies on the crest and its slope is the fall's steepest |grad v|
// (checked against values computed here, not by the rule); a step down from
// brightness, a crest that is not among the brightest, a fall that does not
// reach the isovalue, a fall with no shadow under it (a cyst's wall), a
// crest hardly above the isovalue, held voxels and the switch leave the data
// alone; the
// rule is the same along x and z and for any thread count; an update to a
// new isovalue re-applies it as a fresh build would; and classify's
// default draws a family spine's bone nearer its surface.
#include <cmath>
#include <regex>
#include <string>
#include <vector>

#include "crest.hpp"
#include "variational.hpp"
#include "io.hpp"
#include "metrics.hpp"
#include "cli_fixture.hpp"
#include "test_support.hpp"

namespace softshell {
namespace {

// A volume of `lines` beam lines along z, each the same profile; h mm along
// the beam. Its |grad v|^2 is the central difference along the beam.
struct Lines {
  Dims3 dims;
  Vec3d spacing;
  std::vector<float> vs, grad2;
  std::vector<std::uint8_t> fixed;
};

Lines lines_of(const std::vector<float>& profile, std::size_t lines, double h) {
  Lines l;
  const std::size_t n = profile.size();
  l.dims = {lines, 1, n};
  l.spacing = {1.0, 1.0, h};
  l.vs.resize(lines * n), l.grad2.resize(lines * n), l.fixed.assign(lines * n, 0);
  for (std::size_t z = 0; z < n; ++z) {
    const double g = z == 0 || z + 1 == n ? 0.0 : (profile[z + 1] - profile[z - 1]) / (2 * h);
    for (std::size_t x = 0; x < lines; ++x) l.vs[z * lines + x] = profile[z], l.grad2[z * lines + x] = float(g * g);
  }
  return l;
}

// Dark above (0.2), a ridge rising to 0.9 at index 10, falling to 0.05 (a
// shadow) by index 13; 24 samples. Isovalue 0.5.
std::vector<float> ridge_profile() {
  std::vector<float> p(24, 0.05f);
  for (int i = 0; i < 8; ++i) p[std::size_t(i)] = 0.2f;
  p[8] = 0.45f, p[9] = 0.75f, p[10] = 0.9f, p[11] = 0.7f, p[12] = 0.35f, p[13] = 0.1f;
  return p;
}

TEST(Crest, TheRampsZeroLiesOnTheCrestWithTheFallsSlope) {
  const double h = 0.5, iso = 0.5, shift = 0.4;
  const std::vector<float> p = ridge_profile();
  Lines l = lines_of(p, 3, h);
  CrestParams cp;  // the defaults: ridge 0.25, reach 3 mm, above 2 mm, pad 1.5 mm, quantile 0.97
  cp.quantile = 0.5;  // a line of 24 samples: the crest is its brightest, not among 3 %
  const CrestReport r = crest_shells(l.vs, l.grad2, l.fixed, l.dims, l.spacing, iso, shift, /*g_ref*/ 0.1, cp, 1);
  EXPECT_EQ(r.crests, 3u);
  // The fall's steepest |grad v| between the crest (10) and the first sample
  // under the isovalue (12): central differences at 10, 11, 12.
  double G = 0;
  for (int z = 10; z <= 12; ++z) G = std::max(G, std::fabs(double(p[z + 1] - p[z - 1]) / (2 * h)));
  // The ramp covers the crest - 1.5 mm (3 samples) to the crossing + 3 samples.
  const int from = 10 - 3, to = 12 + 3;
  EXPECT_EQ(r.voxels, 3u * std::size_t(to - from + 1));
  for (std::size_t z = 0; z < p.size(); ++z) {
    const int zi = int(z);
    for (std::size_t x = 0; x < 3; ++x) {
      const std::size_t i = z * 3 + x;
      SCOPED_TRACE("z " + std::to_string(z));
      if (zi >= from && zi <= to) {
        const double d = (zi - 10) * h;
        EXPECT_NEAR(l.vs[i], iso + shift * G + G * d, 1e-5);
        const double g0 = zi == 0 ? 0.0 : std::fabs(double(p[z + 1] - p[z - 1]) / (2 * h));
        EXPECT_NEAR(std::sqrt(l.grad2[i]), std::max(g0, G), 1e-5);
      } else {
        EXPECT_EQ(l.vs[i], p[z]);
      }
    }
  }
  // Where F_iso puts the shell (v~ - shift |grad v| = iso): on the crest.
  const std::size_t c = 10 * 3;
  EXPECT_NEAR(l.vs[c] - shift * std::sqrt(l.grad2[c]), iso, 1e-5);
}

TEST(Crest, StepsFaintCrestsShortFallsHeldVoxelsAndTheSwitchChangeNothing) {
  const double h = 0.5, iso = 0.5;
  CrestParams cp;
  cp.quantile = 0.5;
  const auto unchanged = [&](const std::vector<float>& p, CrestParams c, bool hold_crest, const char* what) {
    Lines l = lines_of(p, 2, h);
    if (hold_crest) l.fixed[10 * 2] = l.fixed[10 * 2 + 1] = 1;
    const std::vector<float> vs = l.vs, g2 = l.grad2;
    const CrestReport r = crest_shells(l.vs, l.grad2, l.fixed, l.dims, l.spacing, iso, 0.4, 0.1, c, 2);
    EXPECT_EQ(r.crests, 0u) << what;
    EXPECT_EQ(l.vs, vs) << what;
    EXPECT_EQ(l.grad2, g2) << what;
  };
  // A step down from a bright region above: no rise from above.
  std::vector<float> step = ridge_profile();
  for (int i = 0; i < 10; ++i) step[std::size_t(i)] = 0.9f - 0.001f * float(10 - i);
  unchanged(step, cp, false, "a step down");
  // The fall does not reach the isovalue within 3 mm (6 samples): a thick echo.
  std::vector<float> thick = ridge_profile();
  for (int i = 11; i < 20; ++i) thick[std::size_t(i)] = 0.8f - 0.01f * float(i - 11);
  unchanged(thick, cp, false, "a fall longer than the reach");
  // The crest under the quantile.
  CrestParams high = cp;
  high.quantile = 0.999;
  std::vector<float> faint = ridge_profile();
  faint[22] = 0.95f;  // the line's brightest samples at its end (no fall after them)
  faint[23] = 0.95f;
  unchanged(faint, high, false, "a crest under the quantile");
  // A cyst's top wall: dark inside, its far wall (above the isovalue) below.
  std::vector<float> cyst = ridge_profile();
  cyst[19] = 0.6f, cyst[20] = 0.7f, cyst[21] = 0.6f;
  unchanged(cyst, cp, false, "no shadow to the end of the line");
  // A speckle grain that just reaches the isovalue: 0.52 - 0.5 < 0.5 x (0.5 - 0.05).
  std::vector<float> grain = ridge_profile();
  grain[9] = 0.45f, grain[10] = 0.52f, grain[11] = 0.48f;
  unchanged(grain, cp, false, "a crest hardly above the isovalue");
  // The crest held at u = 0.
  unchanged(ridge_profile(), cp, true, "the crest held");
  // The fall's edge weaker than min_edge x g_ref.
  CrestParams weak = cp;
  weak.min_edge = 100;
  unchanged(ridge_profile(), weak, false, "a weak edge");
  // The switch.
  CrestParams off = cp;
  off.ridge = 0;
  unchanged(ridge_profile(), off, false, "ridge 0");
  // Without the shadow and lift tests the cyst's walls (top and far: the far
  // one has the line's end under it) and the grain pass.
  CrestParams loose = cp;
  loose.shadow = false, loose.lift = 0;
  for (const std::vector<float>* p : {&cyst, &grain}) {
    Lines l = lines_of(*p, 1, h);
    EXPECT_EQ(crest_shells(l.vs, l.grad2, l.fixed, l.dims, l.spacing, iso, 0.4, 0.1, loose, 1).crests,
              p == &cyst ? 2u : 1u);
  }
}

TEST(Crest, TheSameAlongXAndZAndForAnyThreadCount) {
  const double h = 0.5;
  const std::vector<float> p = ridge_profile();
  CrestParams cp;
  cp.quantile = 0.5;
  // Along z: 5 lines of the profile, the middle one brighter (another crest).
  Lines z = lines_of(p, 5, h);
  for (std::size_t k = 0; k < p.size(); ++k) z.vs[k * 5 + 2] *= 1.05f;
  Lines z2 = z;
  const Lines z0 = z;
  CrestChanges c1, c2;
  const CrestReport rz = crest_shells(z.vs, z.grad2, z.fixed, z.dims, z.spacing, 0.5, 0.4, 0.1, cp, 1, &c1);
  const CrestReport rz2 = crest_shells(z2.vs, z2.grad2, z2.fixed, z2.dims, z2.spacing, 0.5, 0.4, 0.1, cp, 2, &c2);
  EXPECT_EQ(rz.crests, 5u);
  EXPECT_EQ(z.vs, z2.vs);
  EXPECT_EQ(z.grad2, z2.grad2);
  EXPECT_EQ(rz.voxels, rz2.voxels);
  // The changes returned: every voxel that differs from before, with its
  // value before, and nothing else; the same list for both thread counts;
  // restoring them gives the input back.
  EXPECT_EQ(c1.index, c2.index);
  EXPECT_EQ(c1.vs, c2.vs);
  EXPECT_EQ(c1.grad2, c2.grad2);
  ASSERT_EQ(c1.index.size(), rz.voxels);
  ASSERT_EQ(c1.vs.size(), rz.voxels);
  ASSERT_EQ(c1.grad2.size(), rz.voxels);
  std::vector<std::uint8_t> listed(z.vs.size(), 0);
  for (std::size_t k = 0; k < c1.index.size(); ++k) {
    const std::size_t i = c1.index[k];
    ASSERT_LT(i, z.vs.size());
    EXPECT_EQ(listed[i], 0) << "listed twice: " << i;
    listed[i] = 1;
    EXPECT_EQ(c1.vs[k], z0.vs[i]);
    EXPECT_EQ(c1.grad2[k], z0.grad2[i]);
  }
  for (std::size_t i = 0; i < z.vs.size(); ++i)
    if (z.vs[i] != z0.vs[i] || z.grad2[i] != z0.grad2[i]) EXPECT_EQ(listed[i], 1) << "changed, not listed: " << i;
  Lines back = z;
  for (std::size_t k = 0; k < c1.index.size(); ++k) back.vs[c1.index[k]] = c1.vs[k], back.grad2[c1.index[k]] = c1.grad2[k];
  EXPECT_EQ(back.vs, z0.vs);
  EXPECT_EQ(back.grad2, z0.grad2);
  // The transpose: beam along x (dims n x 1 x 5), axis 0.
  const std::size_t n = p.size();
  std::vector<float> xv(n * 5), xg(n * 5), zvs0 = lines_of(p, 5, h).vs, zg0 = lines_of(p, 5, h).grad2;
  for (std::size_t k = 0; k < n; ++k) zvs0[k * 5 + 2] *= 1.05f;
  for (std::size_t k = 0; k < n; ++k)
    for (std::size_t l = 0; l < 5; ++l) xv[l * n + k] = zvs0[k * 5 + l], xg[l * n + k] = zg0[k * 5 + l];
  std::vector<std::uint8_t> xf(n * 5, 0);
  CrestParams cx = cp;
  cx.axis = 0;
  const CrestReport rx = crest_shells(xv, xg, xf, {n, 1, 5}, {h, 1.0, 1.0}, 0.5, 0.4, 0.1, cx, 2);
  EXPECT_EQ(rx.crests, rz.crests);
  for (std::size_t k = 0; k < n; ++k)
    for (std::size_t l = 0; l < 5; ++l) {
      EXPECT_EQ(xv[l * n + k], z.vs[k * 5 + l]) << k << " " << l;
      EXPECT_EQ(xg[l * n + k], z.grad2[k * 5 + l]) << k << " " << l;
    }
}

TEST(Crest, RefusesMismatchedSizesABadAxisAndSpacing) {
  Lines l = lines_of(ridge_profile(), 2, 0.5);
  std::vector<float> short_vs(3);
  EXPECT_THROW(crest_shells(short_vs, l.grad2, l.fixed, l.dims, l.spacing, 0.5, 0.4, 0.1, CrestParams{}, 1),
               std::invalid_argument);
  CrestParams bad;
  bad.axis = 3;
  EXPECT_THROW(crest_shells(l.vs, l.grad2, l.fixed, l.dims, l.spacing, 0.5, 0.4, 0.1, bad, 1), std::invalid_argument);
  EXPECT_THROW(crest_shells(l.vs, l.grad2, l.fixed, l.dims, {1.0, 1.0, 0.0}, 0.5, 0.4, 0.1, CrestParams{}, 1),
               std::invalid_argument);
  // A tiny spacing: the lengths in samples are bounded by the line (no overflow).
  CrestParams cp;
  cp.quantile = 0.5;
  EXPECT_NO_THROW(crest_shells(l.vs, l.grad2, l.fixed, l.dims, {1.0, 1.0, 1e-30}, 0.5, 0.4, 0.1, cp, 1));
}

// A bone seen from above: speckled tissue (0.3), a 2 mm bright plate (1.0)
// at 10-12 mm depth over x < 8 mm, its shadow (0.05) under it to the end;
// the tissue goes on beside it. 0.5 mm voxels, beam along z.
Volume plate_over_shadow() {
  Volume v({24, 16, 40}, {0.5, 0.5, 0.5});
  std::uint32_t state = 12345;
  const auto noise = [&] {
    state = state * 1664525u + 1013904223u;
    return float(state >> 8) / float(1u << 24) - 0.5f;
  };
  for (std::size_t z = 0; z < 40; ++z)
    for (std::size_t y = 0; y < 16; ++y)
      for (std::size_t x = 0; x < 24; ++x) {
        const bool under = x < 16;
        float a = 0.3f + 0.1f * noise();
        if (under && z >= 20 && z < 24) a = 1.0f;
        if (under && z >= 24) a = 0.05f + 0.02f * noise();
        v.at(x, y, z) = a;
      }
  return v;
}

TEST(Crest, AnUpdateReAppliesTheRuleAsAFreshBuildWould) {
  // A new isovalue and shell shift on a built system (the viewer's re-solve):
  // the rule is applied again to the data as they were before it, so the
  // system equals a fresh build's, bit for bit, and the classifier updates
  // in place.
  const Volume v = plate_over_shadow();
  VariationalParams p0;
  p0.v_iso = 0.45;
  p0.crest.ridge = kEchoCrestRidge;
  VariationalParams p1 = p0;
  p1.v_iso = 0.40, p1.shell_shift_mm = 0.3;
  DeviceSystem sys(test::runtime(), v, p0);
  const CrestReport r0 = sys.crest();
  ASSERT_GT(r0.crests, 0u);
  const std::vector<float> before = sys.download_coefficients();
  sys.update_point(p1);
  DeviceSystem fresh(test::runtime(), v, p1);
  test::runtime().queue().finish();
  EXPECT_GT(fresh.crest().crests, 0u);
  EXPECT_EQ(sys.crest().crests, fresh.crest().crests);
  EXPECT_EQ(sys.crest().voxels, fresh.crest().voxels);
  EXPECT_GT(test::max_relative_deviation(before, fresh.download_coefficients()), 1e-3);
  EXPECT_EQ(test::max_relative_deviation(sys.download_coefficients(), fresh.download_coefficients()), 0.0);
  EXPECT_EQ(test::max_relative_deviation(sys.download_b(), fresh.download_b()), 0.0);
  // And back: the first build again.
  sys.update_point(p0);
  test::runtime().queue().finish();
  EXPECT_EQ(test::max_relative_deviation(sys.download_coefficients(), before), 0.0);
  EXPECT_EQ(sys.crest().crests, r0.crests);
  // The classifier updates in place for an isovalue; the rule's own
  // parameters need a new setup.
  VariationalClassifier c(test::runtime(), v, p0);
  EXPECT_TRUE(c.can_update(p1));
  VariationalParams p2 = p0;
  p2.crest.lift = 0.2;
  EXPECT_FALSE(c.can_update(p2));
  VariationalParams off = p0;
  off.crest.ridge = 0;
  EXPECT_FALSE(c.can_update(off));
}

class CliCrest : public test::CliTest {};

TEST_F(CliCrest, ASpinesShellMovesUpToItsBoneAndTheSwitchTurnsItOff) {
  // A family spine (the randomised physics: bone echoes over their shadows)
  // whose surface is known.
  ASSERT_EQ(run({"phantom", "--shape", "spine", "--physics", "random", "--seed", "3102", "--size", "64", "-o",
                 file("spine"), "-q"})
                .status,
            0);
  const test::RunResult off =
      run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "--echo-crest", "0", "-o", file("off.nrrd")});
  ASSERT_EQ(off.status, 0) << off.err;
  EXPECT_NE(off.out.find("echo crest off"), std::string::npos) << off.out;
  // On by default, at 0.25.
  const test::RunResult on = run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "-o", file("on.nrrd")});
  ASSERT_EQ(on.status, 0) << on.err;
  EXPECT_NE(on.out.find("(ridge 0.25,"), std::string::npos) << on.out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(on.out, m, std::regex("echo crest ([0-9]+) crests along ([xyz]), ([0-9]+) voxels")))
      << on.out;
  EXPECT_GT(std::stoul(m[1]), 0u);
  const Volume truth = read_volume(file("spine/truth_sdf.nrrd"));
  const Metrics a = evaluate_opacity(read_volume(file("off.nrrd")), truth, MetricsParams{});
  const Metrics b = evaluate_opacity(read_volume(file("on.nrrd")), truth, MetricsParams{});
  EXPECT_NE(read_volume(file("off.nrrd")).data, read_volume(file("on.nrrd")).data);
  // Measured: F1 0.664 -> 0.711, recall 0.561 -> 0.626, the shell's middle
  // -1.15 -> -1.07 mm along the true outward normal (less deep in the bone).
  EXPECT_GT(b.f1, a.f1 + 0.02) << "off " << a.f1 << ", on " << b.f1;
  EXPECT_GT(b.recall, a.recall + 0.03) << "off " << a.recall << ", on " << b.recall;
  EXPECT_GT(b.shell_offset_mm, a.shell_offset_mm) << "off " << a.shell_offset_mm << ", on " << b.shell_offset_mm;
  EXPECT_GE(b.mass_precision, a.mass_precision - 0.02) << "off " << a.mass_precision << ", on " << b.mass_precision;
  // --literal takes the paper's terms: no crest.
  const test::RunResult lit = run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "--literal", "--echo-crest",
                                   "0.25", "-o", file("lit.nrrd")});
  ASSERT_EQ(lit.status, 0) << lit.err;
  EXPECT_EQ(lit.out.find("echo crest"), std::string::npos) << lit.out;
  ASSERT_EQ(run({"classify", file("spine/volume.nrrd"), "--iso", "auto", "--literal", "--echo-crest", "0", "-o",
                 file("lit0.nrrd"), "-q"})
                .status,
            0);
  EXPECT_EQ(read_volume(file("lit.nrrd")).data, read_volume(file("lit0.nrrd")).data);
  expect_one_line_error(run({"classify", file("spine/volume.nrrd"), "--echo-crest", "2", "-o", file("x.nrrd")}),
                        {"--echo-crest"});
}

}  // namespace
}  // namespace softshell
