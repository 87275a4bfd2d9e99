// The CLI's argument checks (host/cli/cli_validate.hpp), early output checks
// and progress reporting (host/progress.hpp), end to end through the
// `softshell` binary: every number option refuses NaN, infinities and values
// outside its meaning with exit 2 and one line naming the option and its
// range; every list of choices in an error equals the list `--help` shows;
// outputs are checked before any work; progress goes to stderr only on a
// terminal, or as JSON lines when asked.
#include <cmath>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "io.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

using test::CliTest;
using test::RunResult;
using test::slurp;
namespace fs = std::filesystem;

class CliArgs : public CliTest {
 protected:
  // A 16^3 uint8 speckled sphere (values 0-255).
  std::string small_volume() {
    const std::string p = file("s.nrrd");
    if (!fs::exists(p)) {
      const RunResult r = run({"synthetic", "--size", "16", "-q", "-o", p});
      EXPECT_EQ(r.status, 0) << r.err;
    }
    return p;
  }
  // Signed distance in voxels to a sphere of radius r, times `scale`.
  std::string sphere_sdf(const std::string& name, double scale = 1.0, std::size_t n = 16) {
    Volume v({n, n, n});
    const double c = 0.5 * double(n - 1), r = 0.3 * double(n);
    for (std::size_t z = 0; z < n; ++z)
      for (std::size_t y = 0; y < n; ++y)
        for (std::size_t x = 0; x < n; ++x)
          v.at(x, y, z) = float(scale * (std::sqrt((x - c) * (x - c) + (y - c) * (y - c) + (z - c) * (z - c)) - r));
    write_volume(file(name), v);
    return file(name);
  }
};

std::vector<std::string> commands(const CliTest& t, const RunResult& help) {
  (void)t;
  // CLI11 help lists the subcommands after "Subcommands:", one per line.
  std::vector<std::string> names;
  std::istringstream in(help.out);
  std::string line;
  bool in_list = false;
  while (std::getline(in, line)) {
    if (line.rfind("Subcommands:", 0) == 0) {
      in_list = true;
      continue;
    }
    std::smatch m;
    if (in_list && std::regex_search(line, m, std::regex("^  ([a-z0-9]+)\\b"))) names.push_back(m[1]);
  }
  return names;
}

// Options of a command's help: name -> type text ("FLOAT:in [0, 1]").
std::map<std::string, std::string> option_types(const std::string& help) {
  std::map<std::string, std::string> types;
  std::istringstream in(help);
  std::string line;
  const std::regex opt("^\\s+(?:-[a-zA-Z],)?(--[a-z0-9-]+) ([A-Za-z][A-Za-z0-9|,:.\\[\\]()<>=+ -]*?)(?:=\\S*)?(?:  |$)");
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_search(line, m, opt)) types[m[1]] = m[2];
  }
  return types;
}

// ---- the whole CLI: every number option has a range, every list matches -----------------

TEST_F(CliArgs, EveryFloatOptionOfEveryCommandRefusesNanAndInfinityNamingItsRange) {
  const std::vector<std::string> cmds = commands(*this, run({"--help"}));
  ASSERT_GE(cmds.size(), 10u);
  int checked = 0;
  for (const std::string& cmd : cmds) {
    const RunResult h = run({cmd, "--help"});
    ASSERT_EQ(h.status, 0) << cmd;
    for (const auto& [name, type] : option_types(h.out)) {
      if (type.rfind("FLOAT", 0) != 0) continue;
      SCOPED_TRACE(cmd + " " + name + " " + type);
      // The help states the range (or "finite" for a value in the data's units).
      EXPECT_NE(type.find("FLOAT:"), std::string::npos) << "no range in --help";
      for (const char* bad : {"nan", "-inf", "1e999"}) {
        const RunResult r = run({cmd, name, bad});
        expect_one_line_error(r, {name + ": must be a finite number", std::string("got '") + bad + "'"});
      }
      ++checked;
    }
  }
#ifdef SOFTSHELL_HAVE_VIEWER
  EXPECT_EQ(checked, 66);  // classify alone has 35 (--small-volume the 26th, --shell-shift the 27th, --iso-clip-fraction the 28th, --iso-field-depth-sigma the 29th, --iso-floor-fraction the 30th, --iso-bulk-spread the 31st, --edge-split the 32nd, --edge-split-from the 33rd, --echo-crest the 34th, --iso-climb the 35th); view --overlay; evaluate --visible-db; phantom --turn, --drift
#else
  EXPECT_EQ(checked, 51);  // without render, view, figure5, figure6
#endif
}

TEST_F(CliArgs, EveryListOfChoicesInAnErrorEqualsTheHelpList) {
  int checked = 0;
  for (const std::string& cmd : commands(*this, run({"--help"}))) {
    for (const auto& [name, type] : option_types(run({cmd, "--help"}).out)) {
      const auto at = type.find("one of: ");
      if (at == std::string::npos) continue;
      SCOPED_TRACE(cmd + " " + name);
      const std::string list = type.substr(at + 8);
      const RunResult r = run({cmd, name, "bogus"});
      expect_one_line_error(r, {name + ": unknown value 'bogus' (expected " + list + ")"});
      ++checked;
    }
  }
  EXPECT_GE(checked, 6);
}

// ---- the holes of issue 16, one by one --------------------------------------------------

TEST_F(CliArgs, SigmaMinusOneAndNanAreRefusedNotReplaced) {
  const std::string in = small_volume();
  for (const char* cmd : {"classify", "lowpass"}) {
    for (const char* bad : {"-1", "nan", "inf"}) {
      SCOPED_TRACE(std::string(cmd) + " --sigma " + bad);
      std::vector<std::string> args{cmd, in, "-o", file("u.nrrd"), "--sigma", bad};
      if (std::string(cmd) == "classify") args.insert(args.end(), {"--iso", "100"});
      expect_one_line_error(run(args), {"--sigma: must be a finite number >= 0 mm, got '" + std::string(bad) + "'"});
    }
  }
  expect_one_line_error(run({"classify", in, "--method", "levoy", "--iso", "100", "--sigma", "-1", "-o", file("u.nrrd")}),
                        {"--sigma: must be a finite number >= 0 mm"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
}

TEST_F(CliArgs, AlphaNanIsABadArgumentNotANonConvergence) {
  const RunResult r = run({"classify", small_volume(), "--iso", "100", "--alpha", "nan", "-o", file("u.nrrd")});
  expect_one_line_error(r, {"--alpha: must be a finite number in [0, 1e+06], got 'nan'"});
}

TEST_F(CliArgs, UIndMustBeAnOpacity) {
  const std::string in = small_volume();
  for (const char* bad : {"5", "0", "-1", "1.01"}) {
    SCOPED_TRACE(bad);
    expect_one_line_error(run({"classify", in, "--iso", "100", "--u-ind", bad, "-o", file("u.nrrd")}),
                          {"--u-ind: must be a finite number in (0, 1], got '" + std::string(bad) + "'"});
    expect_one_line_error(run({"evaluate", in, in, "--u-ind", bad}), {"--u-ind: must be a finite number in (0, 1]"});
  }
}

TEST_F(CliArgs, IsoOutsideTheDataWarnsOnce) {
  const std::string in = small_volume();  // uint8, values within [0, 255]
  for (const char* iso : {"300", "-5"}) {
    SCOPED_TRACE(iso);
    const RunResult r = run({"classify", in, "--iso", iso, "-q", "-o", file("u.nrrd"), "--max-cycles", "5000"});
    EXPECT_NE(r.status, 2) << r.err;  // runs (or does not converge): a warning, not an error
    EXPECT_EQ(r.err.rfind("softshell: warning: --iso " + std::string(iso) + " is outside the data's value range [", 0), 0u)
        << r.err;
    EXPECT_NE(r.err.find("(uint8 samples); no boundary lies at that value\n"), std::string::npos) << r.err;
  }
  // Inside the range: silent.
  const RunResult ok = run({"classify", in, "--iso", "100", "-q", "-o", file("u.nrrd")});
  EXPECT_EQ(ok.status, 0) << ok.err;
  EXPECT_EQ(ok.err, "");
  // Levoy's classifier warns the same way.
  const RunResult lv = run({"classify", in, "--method", "levoy", "--iso", "300", "-q", "-o", file("l.nrrd")});
  EXPECT_EQ(lv.status, 0) << lv.err;
  EXPECT_NE(lv.err.find("warning: --iso 300 is outside"), std::string::npos) << lv.err;
  // And figure2.
  const RunResult f2 = run({"figure2", in, "--iso", "-5", "--mask", "none", "-q", "-o", file("f2.png")});
  EXPECT_NE(f2.status, 2) << f2.err;
  EXPECT_NE(f2.err.find("warning: --iso -5 is outside the data's value range [0, "), std::string::npos) << f2.err;
}

TEST_F(CliArgs, EvaluateRefusesATruthThatIsNoSignedDistance) {
  const std::string in = small_volume();
  const std::string sdf = sphere_sdf("sdf.nrrd");
  // A shell of opacity around the true sphere: accepted.
  Volume u = read_volume(sdf);
  for (float& f : u.data) f = float(std::max(0.0, 1.0 - std::abs(f) / 1.5));
  write_volume(file("u.nrrd"), u);
  RunResult r = run({"evaluate", file("u.nrrd"), sdf, "--json"});
  ASSERT_EQ(r.status, 0) << r.err;
  // The B-mode volume as the truth (the case): no sign change.
  r = run({"evaluate", file("u.nrrd"), in});
  expect_one_line_error(r, {in + ": TRUTH_SDF does not look like a signed distance in voxels: its values lie in [",
                            "with no sign change"});
  EXPECT_TRUE(r.out.empty()) << r.out;
  // The opacity as the truth: no sign change either.
  expect_one_line_error(run({"evaluate", file("u.nrrd"), file("u.nrrd")}), {"no sign change"});
  // A distance in other units (x10): |grad| 10 next to the zero set.
  expect_one_line_error(run({"evaluate", file("u.nrrd"), sphere_sdf("sdf10.nrrd", 10.0)}),
                        {"the median |grad| next to its zero set is 9.9", "not near 1"});
  // Half-voxel units still pass (|grad| 0.5 is the edge of what is accepted: 0.6 here).
  EXPECT_EQ(run({"evaluate", file("u.nrrd"), sphere_sdf("sdf06.nrrd", 0.6)}).status, 0);
}

TEST_F(CliArgs, EvaluateTakesAnAnisotropicTruthInUnitsOfTheSmallestSpacing) {
  // A cylinder along z on a grid of 0.8 x 0.8 x 0.35 mm: every surface faces
  // across x and y, where the distance in units of the smallest spacing
  // (0.35 mm) changes by 0.8 / 0.35 = 2.29 per voxel index. It is a signed
  // distance (docs/metrics.md, "Units and anisotropic voxels"): accepted. The
  // same distance in millimetres changes by 0.35 per smallest spacing, a
  // distance in other units: refused.
  const std::size_t nx = 24, ny = 24, nz = 20;
  const auto cylinder = [&](const std::string& name, double unit_mm) {
    Volume v({nx, ny, nz});
    v.spacing = {0.8, 0.8, 0.35};
    const double c = 0.5 * double(nx - 1), r_mm = 6.0;
    for (std::size_t z = 0; z < nz; ++z)
      for (std::size_t y = 0; y < ny; ++y)
        for (std::size_t x = 0; x < nx; ++x) {
          const double dx = (double(x) - c) * 0.8, dy = (double(y) - c) * 0.8;
          v.at(x, y, z) = float((std::sqrt(dx * dx + dy * dy) - r_mm) / unit_mm);
        }
    write_volume(file(name), v);
    return file(name);
  };
  const std::string sdf = cylinder("cyl.nrrd", 0.35);
  Volume u = read_volume(sdf);
  for (float& f : u.data) f = float(std::max(0.0, 1.0 - std::abs(f) / 1.5));
  write_volume(file("u.nrrd"), u);
  const RunResult r = run({"evaluate", file("u.nrrd"), sdf, "--json"});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.out.find("\"precision\": 1"), std::string::npos) << r.out;
  expect_one_line_error(run({"evaluate", file("u.nrrd"), cylinder("cyl_mm.nrrd", 1.0)}),
                        {"the median |grad| next to its zero set is 0.34", "not near 1"});
}

TEST_F(CliArgs, InitMustBeAnOpacityVolume) {
  const std::string in = small_volume();
  ASSERT_EQ(run({"classify", in, "--iso", "100", "-q", "-o", file("u0.nrrd")}).status, 0);
  // A signed distance (negative values) and the B-mode input: refused, named.
  const std::string sdf = sphere_sdf("sdf.nrrd");
  RunResult r = run({"classify", in, "--iso", "100", "--sharpen", "0", "--init", sdf, "-o", file("u.nrrd")});
  expect_one_line_error(r, {sdf + ": --init is not an opacity volume: its values lie in [-3.9", "in [0, 1]"});
  r = run({"classify", in, "--iso", "100", "--sharpen", "0", "--init", in, "-o", file("u.nrrd")});
  expect_one_line_error(r, {in + ": --init is not an opacity volume: its values lie in [0, "});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
  // A previous classification: accepted.
  r = run({"classify", in, "--iso", "100", "--sharpen", "0", "--init", file("u0.nrrd"), "-q", "-o", file("u.nrrd")});
  EXPECT_EQ(r.status, 0) << r.err;
}

TEST_F(CliArgs, OutputExtensionsMustMatchTheWriter) {
  const std::string in = small_volume();
  RunResult r = run({"slices", in, "-o", file("s.jpg")});
  expect_one_line_error(r, {"-o " + file("s.jpg") + ": unknown extension '.jpg' for a PNG image (writes .png)"});
  r = run({"classify", in, "--iso", "100", "-o", file("u.vtk")});
  expect_one_line_error(r, {"unknown extension '.vtk' for a volume (writes .nrrd, .mha, .mhd, .nii, .nii.gz or .vti)"});
  r = run({"lowpass", in, "-o", file("u")});
  expect_one_line_error(r, {"no extension for a volume (writes .nrrd, .mha, .mhd, .nii, .nii.gz or .vti)"});
  r = run({"synthetic", "-o", file("s.png")});
  expect_one_line_error(r, {"unknown extension '.png' for a volume"});
  r = run({"figure2", in, "-o", file("f.nrrd")});
  expect_one_line_error(r, {"unknown extension '.nrrd' for a PNG image"});
  r = run({"phantom", "--size", "16", "-o", file("ph"), "--slices", file("s.jpeg")});
  expect_one_line_error(r, {"--slices " + file("s.jpeg") + ": unknown extension '.jpeg' for a PNG image"});
  // Nothing written (s.nrrd is the input).
  EXPECT_EQ(listing(), std::vector<std::string>{"s.nrrd"});
  ASSERT_EQ(run({"slices", in, "-q", "-o", file("s.PNG")}).status, 0);
}

#ifdef SOFTSHELL_HAVE_VIEWER
TEST_F(CliArgs, RenderAndViewMethodsEqualTheirHelp) {
  const std::string in = small_volume();
  const auto listed = [&](const std::string& cmd) {
    const std::string type = option_types(run({cmd, "--help"}).out)["--method"];
    const auto at = type.find("one of: ");
    return at == std::string::npos ? std::string() : type.substr(at + 8);
  };
  EXPECT_EQ(listed("render"), "splat, isosplat, raycast, mc or shearwarp");
  EXPECT_EQ(listed("view"), "splat, isosplat, mc or raycast");
  expect_one_line_error(run({"render", in, "-o", file("a.png"), "--method", "foo"}),
                        {"--method: unknown value 'foo' (expected splat, isosplat, raycast, mc or shearwarp)"});
  // view: shear-warp is not interactive, and its help no longer offers it.
  expect_one_line_error(run({"view", in, "--method", "shearwarp"}),
                        {"--method: unknown value 'shearwarp' (expected splat, isosplat, mc or raycast)"});
  EXPECT_EQ(run({"view", "--help"}).out.find("shearwarp"), std::string::npos);
  // What view's help offers passes the argument checks (and then fails on
  // the missing file, past them).
  for (const char* m : {"splat", "isosplat", "mc", "raycast"}) {
    SCOPED_TRACE(m);
    expect_one_line_error(run({"view", file("missing.nrrd"), "--method", m, "--frames", "1"}), {"missing.nrrd"});
  }
}
#endif

TEST_F(CliArgs, IntegerOptionsNameTheirRange) {
  const std::string in = small_volume();
  expect_one_line_error(run({"classify", in, "--iso", "100", "--levels", "0", "-o", file("u.nrrd")}),
                        {"--levels: must be an integer in [1, 64], got '0'"});
  expect_one_line_error(run({"classify", in, "--iso", "100", "--max-cycles", "1e3", "-o", file("u.nrrd")}),
                        {"--max-cycles: must be an integer in [1, 100000], got '1e3'"});
  expect_one_line_error(run({"phantom", "--size", "8", "-o", file("p")}), {"--size: must be an integer in [16, 512] voxels"});
  expect_one_line_error(run({"slices", in, "--height", "-3", "-o", file("s.png")}),
                        {"--height: must be an integer in [0, 4096] pixels"});
}

// ---- outputs checked before any work ------------------------------------------------------

TEST_F(CliArgs, UnwritableOutputsAreRefusedBeforeAnyWork) {
  const std::string in = small_volume();
  // A regular file where a directory should be: ENOTDIR even for root.
  write("file", "x");
  const std::string bad = file("file") + "/out";
  struct Case {
    std::vector<std::string> args;
    std::string option;
  };
  std::vector<Case> cases = {
      {{"classify", in, "--iso", "100", "-o", bad + ".nrrd"}, "-o " + bad + ".nrrd"},
      {{"classify", in, "--iso", "100", "-o", bad + ".mhd"}, "-o " + bad + ".mhd"},
      {{"lowpass", in, "-o", bad + ".nrrd"}, "-o " + bad + ".nrrd"},
      {{"mesh", in, "--level", "100", "-o", bad + ".ply"}, "-o " + bad + ".ply"},
      {{"slices", in, "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"synthetic", "-o", bad + ".nrrd"}, "-o " + bad + ".nrrd"},
      {{"figure2", in, "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"phantom", "--size", "16", "-o", bad}, "-o " + bad},
      {{"phantom", "--size", "16", "-o", file("ph"), "--slices", bad + ".png"}, "--slices " + bad + ".png"},
#ifdef SOFTSHELL_HAVE_VIEWER
      {{"render", in, "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"render", in, "--turntable", "3", "-o", bad + ".png"}, "-o " + bad + "-000.png"},
      {{"render", in, "--method", "mc", "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"render", in, "--method", "raycast", "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"view", in, "--frames", "1", "--screenshot", bad + ".png"}, "--screenshot " + bad + ".png"},
      {{"figure5", in, "-o", bad + ".png"}, "-o " + bad + ".png"},
      {{"figure6", in, "-o", bad + ".png"}, "-o " + bad + ".png"},
#endif
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.args[0] + " " + c.option);
    // No display and no device are needed to fail here: the check comes first.
    const RunResult r = run(c.args, {"DISPLAY=", "WAYLAND_DISPLAY="});
    expect_one_line_error(r, {c.option});
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
  EXPECT_EQ(listing(), (std::vector<std::string>{"file", "s.nrrd"}));
}

TEST_F(CliArgs, AnExistingOutputSurvivesAFailedRun) {
  const std::string in = small_volume();
  write("u.nrrd", "previous result");
  // Checked writable, then the solve fails (exit 3): the old file is intact
  // and no temporary is left.
  const RunResult r = run({"classify", in, "--iso", "100", "--max-cycles", "1", "--tol", "1e-12", "-o", file("u.nrrd")});
  EXPECT_EQ(r.status, 3) << r.err;
  EXPECT_EQ(slurp(file("u.nrrd")), "previous result");
  EXPECT_EQ(listing(), (std::vector<std::string>{"s.nrrd", "u.nrrd"}));
}

// ---- progress ---------------------------------------------------------------------------

TEST_F(CliArgs, ProgressIsSilentWhenStderrIsNoTerminal) {
  const std::string in = small_volume();
  const RunResult r = run({"classify", in, "--iso", "100", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_NE(r.out.find("classify (variational)"), std::string::npos);
  EXPECT_EQ(r.out.find('\r'), std::string::npos);
}

TEST_F(CliArgs, ProgressJsonIsOneObjectPerLine) {
  const std::string in = small_volume();
  const RunResult r = run({"classify", in, "--iso", "100", "-q", "--progress", "json", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.out, "");
  std::istringstream lines(r.err);
  std::string line;
  std::set<std::string> started, ended;
  const std::regex object(
      "^\\{\"stage\":\"([^\"]+)\",\"event\":\"(start|progress|end)\",\"elapsed_s\":[0-9.]+"
      "(,\"fraction\":[0-9.]+)?(,\"eta_s\":[0-9.]+)?(,\"detail\":\"[^\"]*\")?\\}$");
  int n = 0;
  while (std::getline(lines, line)) {
    std::smatch m;
    ASSERT_TRUE(std::regex_match(line, m, object)) << line;
    (m[2] == "start" ? started : m[2] == "end" ? ended : started).insert(m[1]);
    ++n;
  }
  EXPECT_GE(n, 8);
  for (const char* stage : {"classify", "classify/read", "classify/mask", "classify/setup (lowpass, gradients, system, levels)",
                            "classify/solve (PCG)", "classify/write"}) {
    EXPECT_TRUE(started.count(stage)) << stage << " not started in:\n" << r.err;
    EXPECT_TRUE(ended.count(stage)) << stage << " not ended in:\n" << r.err;
  }
  // The last line closes the command.
  EXPECT_NE(r.err.rfind("{\"stage\":\"classify\",\"event\":\"end\""), std::string::npos);
}

TEST_F(CliArgs, ProgressBarRewritesOneLineAndClearsIt) {
  const std::string in = small_volume();
  RunResult r = run({"classify", in, "--iso", "100", "--progress", "bar", "-o", file("u.nrrd")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_EQ(r.err.find('\n'), std::string::npos) << "the progress line never ends a line";
  EXPECT_NE(r.err.find("\r\033[Kclassify/solve (PCG)"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.substr(r.err.size() - 4), "\r\033[K");  // cleared at the end
  // --quiet silences the default (auto) but not an explicit request.
  r = run({"classify", in, "--iso", "100", "-q", "-o", file("u.nrrd")});
  EXPECT_EQ(r.err, "");
  r = run({"classify", in, "--iso", "100", "--progress", "none", "-o", file("u.nrrd")});
  EXPECT_EQ(r.err, "");
  // Phantom and lowpass report their stages too.
  r = run({"phantom", "--shape", "sphere", "--size", "16", "-q", "--progress", "json", "-o", file("ph")});
  ASSERT_EQ(r.status, 0) << r.err;
  EXPECT_NE(r.err.find("{\"stage\":\"phantom\",\"event\":\"start\""), std::string::npos) << r.err;
  r = run({"lowpass", in, "-q", "--progress", "json", "-o", file("l.nrrd")});
  EXPECT_NE(r.err.find("{\"stage\":\"lowpass\",\"event\":\"end\""), std::string::npos) << r.err;
}

}  // namespace
}  // namespace softshell
