// End-to-end checks of the `softshell` binary's contract for bad input: for
// every kind of broken or unreadable file, exit status 2 and exactly one
// line on stderr naming the file and the problem; a run never clobbers its
// input and a failed run leaves no output or temporary files behind.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "io.hpp"
#include "test_support.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

using test::CliTest;
using test::RunResult;
using test::slurp;
namespace fs = std::filesystem;

const std::string kNrrd3 = "NRRD0004\ntype: uint16\ndimension: 3\nendian: little\nencoding: raw\n";

// ---- one case per kind of bad input ---------------------------------------------------

TEST_F(CliTest, TruncatedNrrd) {
  const std::string p = write("trunc.nrrd", kNrrd3 + "sizes: 4 4 4\n\nabc");
  info_fails(p, {p + ": data truncated: expected 128 bytes of raw data, found 3 after the header"});
  const std::string gz = write("trunc_gz.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 4 4\n"
                                                "endian: little\nencoding: gzip\n\nabc");
  info_fails(gz, {gz + ": corrupt gzip data after 0 bytes: incorrect header check"});
}

TEST_F(CliTest, TruncatedMhaUncompressed) {
  const std::string p = write("t.mha", "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\n"
                                       "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  info_fails(p, {p + ": data truncated: expected 64 bytes, found 3"});
}

TEST_F(CliTest, TruncatedMhaCompressed) {
  Volume v({16, 16, 16}, {1, 1, 1}, ScalarType::UInt16);
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<float>((i * 7919) % 65536);
  WriteOptions z;
  z.compress = true;
  write_volume(file("full.mha"), v, z);
  const std::string full = slurp(file("full.mha"));
  const std::string cut = full.substr(0, full.size() - full.size() / 3);
  const std::string p = write("cut.mha", cut);
  info_fails(p, {p + ": compressed data truncated: CompressedDataSize = "});
  // Without CompressedDataSize the reader inflates to the end of the file.
  std::string nosize = cut;
  const auto a = nosize.find("CompressedDataSize");
  nosize.erase(a, nosize.find('\n', a) + 1 - a);
  const std::string q = write("cut2.mha", nosize);
  info_fails(q, {q + ": data truncated: expected 8192 bytes after decompression"});
}

TEST_F(CliTest, RawSizeDisagreesWithDims) {
  const std::string p = write("v.raw", std::string(100, '\0'));
  info_fails(p, {p + ": file has 100 bytes, but 17x23x9 uint16 needs 7038 bytes"},
             {"--raw", "17,23,9", "--type", "uint16"});
  info_fails(p, {"--raw", "expected X,Y,Z with positive integers, got '17,x,9'"},
             {"--raw", "17,x,9", "--type", "uint16"});
}

TEST_F(CliTest, DimsWhoseProductOverflows) {
  const std::string p = write("ovf.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\n"
                                          "sizes: 4294967296 4294967296 4294967296\nencoding: raw\n\nabc");
  info_fails(p, {p + ": sizes 4294967296 4294967296 4294967296 overflow the voxel count"});
  // Fits size_t as a count, overflows as bytes: caught by our own check.
  const std::string q = write("ovf2.nrrd", "NRRD0004\ntype: float\ndimension: 3\nendian: little\n"
                                           "sizes: 2000000 2000000 2000000\nencoding: raw\n\nabc");
  info_fails(q, {q + ": dims 2000000x2000000x2000000 overflow the voxel count"});
  const std::string m = write("ovf.mha", "NDims = 3\nDimSize = 4294967296 4294967296 4294967296\n"
                                         "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  info_fails(m, {m + ": dims 4294967296x4294967296x4294967296 overflow the voxel count"});
  const std::string r = write("ovf.raw", "abc");
  info_fails(r, {r + ": dims 4294967296x4294967296x4294967296 overflow"},
             {"--raw", "4294967296,4294967296,4294967296", "--type", "uint8"});
}

TEST_F(CliTest, DimsExceedingMemory) {
  const std::string p = write("big.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\n"
                                          "sizes: 100000 100000 1000\nencoding: raw\n\nabc");
  info_fails(p, {p + ": a 100000x100000x1000 uint8 volume needs", "memory"});
  const std::string m = write("big.mha", "NDims = 3\nDimSize = 100000 100000 1000\n"
                                         "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  info_fails(m, {m + ": a 100000x100000x1000 uint8 volume needs", "memory"});
}

TEST_F(CliTest, TwoAndFourDimensionalNrrd) {
  const std::string d2 = write("d2.nrrd", "NRRD0004\ntype: uint8\ndimension: 2\nsizes: 4 5\nencoding: raw\n\n" +
                                              std::string(20, 'x'));
  info_fails(d2, {d2 + ": expected a 3-D scalar volume, found 2-D data (sizes 4 5)"});
  // 4-D: a sequence of frames (info counts them; tests/test_world.cpp), unless its last axis holds
  // something else.
  const std::string d4 = write("d4.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 4 5 2\n"
                                          "kinds: domain domain domain complex\nencoding: raw\n\n" + std::string(120, 'x'));
  info_fails(d4, {d4 + ": expected a 3-D scalar volume or a sequence of them, found 4-D data (sizes 3 4 5 2) whose "
                       "last axis (kind complex) is not a list of frames"});
  const std::string m2 = write("d2.mha", "NDims = 2\nDimSize = 4 5\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n" +
                                             std::string(20, 'x'));
  info_fails(m2, {m2 + ": expected a 3-D scalar volume, found 2-D data"});
}

TEST_F(CliTest, UnknownSampleType) {
  const std::string b = write("block.nrrd", "NRRD0004\ntype: block\nblock size: 4\ndimension: 3\nsizes: 2 2 2\n"
                                            "endian: little\nencoding: raw\n\n" + std::string(32, 'x'));
  info_fails(b, {b + ": unsupported NRRD type 'block'"});
  // Without "endian", Teem itself rejects the header; still one line.
  const std::string b2 = write("block2.nrrd", "NRRD0004\ntype: block\nblock size: 4\ndimension: 3\nsizes: 2 2 2\n"
                                              "encoding: raw\n\n" + std::string(32, 'x'));
  info_fails(b2, {b2 + ": ", "block"});
  const std::string m = write("foo.mha", "ObjectType = Image\nNDims = 3\nDimSize = 2 2 2\nElementType = MET_FOO\n"
                                         "ElementDataFile = LOCAL\n" + std::string(8, 'x'));
  info_fails(m, {m + ": unknown ElementType MET_FOO"});
  const std::string r = write("v.raw", "abcdefgh");
  info_fails(r, {"uint12"}, {"--raw", "2,2,2", "--type", "uint12"});
}

TEST_F(CliTest, UnreadablePath) {
  info_fails(file("missing.nrrd"), {file("missing.nrrd") + ": cannot open: No such file or directory"});
  fs::create_directory(file("adir.nrrd"));
  info_fails(file("adir.nrrd"), {file("adir.nrrd") + ": cannot open: Is a directory"});
  // A folder without a volume file's name is read as a DICOM series (when the build has DICOM).
  info_fails(dir_, {dir_ + (dicom_supported() ? ": a folder with no DICOM image in it" : ": cannot open: Is a directory")});
  if (::geteuid() != 0) {  // root reads anything
    const std::string p = write("secret.nrrd", kNrrd3 + "sizes: 1 1 1\n\nab");
    fs::permissions(p, fs::perms::none);
    info_fails(p, {p + ": cannot open: Permission denied"});
  }
  // A detached header whose data file is missing names both.
  const std::string h = write("h.mhd", "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nElementDataFile = gone.raw\n");
  info_fails(h, {h + ": data file ", "gone.raw: cannot open: No such file or directory"});
  const std::string n = write("h.nhdr", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\ndata file: gone.raw\n"
                                        "encoding: raw\n");
  info_fails(n, {n + ": ", "gone.raw"});
}

TEST_F(CliTest, UnknownExtension) {
  const std::string p = write("volume.xyz", "hello world");
  info_fails(p, {p + ": unrecognised format (expected .nrrd, .nhdr, .mha, .mhd, .nii, .nii.gz, .hdr, .vti, .vol (Kretz), DICOM (.dcm or a series folder), or --raw X,Y,Z --type T)"});
}

TEST_F(CliTest, GarbledHeaders) {
  const std::string n = write("g.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2\x01 2\nspacings 1 1 1\n\n");
  info_fails(n, {n + ": "});
  const std::string m = write("g.mha", "NDims = 3\nthis is not a key value line\n");
  info_fails(m, {m + ": malformed header line 2"});
  const std::string b = write("g2.mha", std::string("\x89PNG\r\n\x1a\n\0\0\0\rIHDR", 16));
  info_fails(b, {b + ": "});
  const std::string e = write("empty.nrrd", "");
  info_fails(e, {e + ": "});
}

// ---- outputs ----------------------------------------------------------------------------

TEST_F(CliTest, LowpassRefusesToOverwriteItsInput) {
  Volume v({6, 5, 4}, {1, 1, 1}, ScalarType::UInt8);
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<float>(i % 251);
  write_volume(file("in.nrrd"), v);
  const std::string before = slurp(file("in.nrrd"));
  const auto mtime = fs::last_write_time(file("in.nrrd"));

  const RunResult r = run({"lowpass", file("in.nrrd"), "--sigma", "1", "-o", file("in.nrrd")});
  expect_one_line_error(r, {file("in.nrrd") + ": output would overwrite the input file"});
  // Another spelling of the same path.
  const RunResult r2 = run({"lowpass", file("in.nrrd"), "--sigma", "1", "-o", dir_ + "/./in.nrrd"});
  expect_one_line_error(r2, {"output would overwrite the input file"});

  EXPECT_EQ(slurp(file("in.nrrd")), before);
  EXPECT_EQ(fs::last_write_time(file("in.nrrd")), mtime);
  EXPECT_EQ(listing(), std::vector<std::string>{"in.nrrd"});
}

TEST_F(CliTest, FailedLowpassLeavesNothingBehind) {
  const std::string bad = write("bad.nrrd", kNrrd3 + "sizes: 4 4 4\n\nabc");
  for (const char* out : {"out.nrrd", "out.mha", "out.mhd"}) {
    const RunResult r = run({"lowpass", bad, "--sigma", "1", "-o", file(out)});
    SCOPED_TRACE(out);
    expect_one_line_error(r, {bad + ": ", "truncated"});
  }
  EXPECT_EQ(listing(), std::vector<std::string>{"bad.nrrd"});  // no outputs, no .tmp files
}

TEST_F(CliTest, UnknownOutputExtension) {
  Volume v({6, 5, 4}, {1, 1, 1}, ScalarType::UInt8);
  write_volume(file("in.nrrd"), v);
  const RunResult r = run({"lowpass", file("in.nrrd"), "--sigma", "1", "-o", file("out.xyz")});
  // Refused before any work (host/cli/cli_validate.hpp), with the extensions the writer knows.
  expect_one_line_error(r, {"-o " + file("out.xyz") + ": unknown extension '.xyz' for a volume (writes .nrrd, .mha, .mhd, .nii, .nii.gz or .vti)"});
  EXPECT_EQ(listing(), std::vector<std::string>{"in.nrrd"});
}

TEST_F(CliTest, InfoOnAGoodFileSucceeds) {
  Volume v({6, 5, 4}, {0.5, 0.5, 2}, ScalarType::Int16);
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = static_cast<float>(i);
  write_volume(file("ok.mha"), v);
  const RunResult r = run({"info", file("ok.mha")});
  EXPECT_EQ(r.status, 0) << r.err;
  EXPECT_TRUE(r.err.empty()) << r.err;
  EXPECT_NE(r.out.find("6 x 5 x 4"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("int16"), std::string::npos) << r.out;
}

// A small object's walls (docs/parameters.md): a dark ball 5 mm across in
// noisy tissue. Its walls are 1-2 % of the voxels, so the top 3 % of the
// gradients is half noise, and F_ind gives the noise's edges an object's
// weight; the rule takes the reference from the top 1 % (the walls), says
// so, and draws the ball's shell with much less haze in the tissue.
TEST_F(CliTest, ClassifyTakesASmallObjectsWallsAsTheReferenceEdge) {
  const std::size_t N = 64;
  const double h = 0.5, c = 0.5 * double(N - 1) * h, radius = 2.5;
  Volume v({N, N, N}, {h, h, h}, ScalarType::UInt8);
  std::mt19937_64 rng(test::seed());
  std::normal_distribution<double> noise(0.0, 12.0);
  std::vector<double> dist(v.voxels());  // from the ball's surface, mm
  for (std::size_t z = 0, i = 0; z < N; ++z)
    for (std::size_t y = 0; y < N; ++y)
      for (std::size_t x = 0; x < N; ++x, ++i) {
        const double r = std::sqrt(std::pow(double(x) * h - c, 2) + std::pow(double(y) * h - c, 2) +
                                   std::pow(double(z) * h - c, 2));
        dist[i] = std::fabs(r - radius);
        v.data[i] = float(std::clamp(std::round((r < radius ? 20.0 : 150.0) + noise(rng)), 1.0, 255.0));
      }
  write_volume(file("ball.nrrd"), v);
  struct Drawn {
    std::size_t near = 0, far = 0;
  };
  auto classify = [&](const std::vector<std::string>& extra, std::string& report) {
    std::vector<std::string> args{"classify", file("ball.nrrd"), "-o", file("u.nrrd"), "--iso", "auto",
                                  "--mask", "none", "--near-field", "keep"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    EXPECT_EQ(r.status, 0) << r.err;
    report = r.out;
    const Volume u = read_volume(file("u.nrrd"));
    Drawn d;
    for (std::size_t i = 0; i < u.voxels(); ++i)
      if (u.data[i] > 0.2f) (dist[i] <= 1.5 ? d.near : d.far) += 1;
    return d;
  };
  std::string split, off;
  const Drawn a = classify({}, split), b = classify({"--edge-split", "0"}, off);
  EXPECT_NE(split.find("(top 1.0 %: its median "), std::string::npos) << split;
  EXPECT_NE(split.find("a small object's walls among speckle"), std::string::npos) << split;
  EXPECT_NE(off.find(" per mm (top 3.0 %)"), std::string::npos) << off;
  // The ball's shell is drawn either way ...
  EXPECT_GT(a.near, 200u);
  EXPECT_GT(b.near, 200u);
  // ... the haze away from it is cut at least in half.
  EXPECT_LT(2 * a.far, b.far) << "far from the ball: " << a.far << " with the rule, " << b.far << " without";
  // Thresholds that put the ratio halfway between --edge-split-from and
  // --edge-split: the two medians blended half and half, and the report
  // says so.
  const std::size_t at = split.find("its median ");
  ASSERT_NE(at, std::string::npos) << split;
  const double ratio = std::stod(split.substr(at + 11));
  ASSERT_GT(ratio, 2.0);
  std::string blend;
  const Drawn m = classify({"--edge-split", std::to_string(1.25 * ratio), "--edge-split-from", std::to_string(0.75 * ratio)}, blend);
  EXPECT_NE(blend.find("(top 3.0 % and top 1.0 % blended, 50 % the latter: its median "), std::string::npos) << blend;
  EXPECT_GT(m.near, 200u);
}

}  // namespace
}  // namespace softshell
