// Tests of the volume I/O layer: round trips through every format and
// several sample types, NRRD encodings written by Teem itself, hand-written
// MetaImage and raw files, the two real ultrasound volumes, statistics and
// intensity normalisation with known answers, and garbled headers.
#include <gtest/gtest.h>
#include <teem/nrrd.h>
#include <unistd.h>
#include <zlib.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "error.hpp"
#include "io.hpp"
#include "test_support.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

namespace fs = std::filesystem;

// ---- helpers -------------------------------------------------------------------

// A fresh directory per test, removed afterwards.
class ScratchDir {
 public:
  ScratchDir() {
    std::string pattern = (fs::path(::testing::TempDir()) / "softshell-io-XXXXXX").string();
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    if (!::mkdtemp(buf.data())) throw std::runtime_error("mkdtemp failed");
    path_ = buf.data();
  }
  ~ScratchDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  std::string file(const std::string& name) const { return (fs::path(path_) / name).string(); }
  const std::string& path() const { return path_; }
  std::vector<std::string> listing() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(path_)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  std::string path_;
};

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

template <typename T>
std::string as_bytes(const std::vector<T>& v, bool big_endian = false) {
  std::string s(reinterpret_cast<const char*>(v.data()), v.size() * sizeof(T));
  if (big_endian) {
    for (std::size_t i = 0; i < s.size(); i += sizeof(T)) std::reverse(&s[i], &s[i] + sizeof(T));
  }
  return s;
}

// Samples exactly representable in `t`, spread over its range.
Volume test_volume(ScalarType t, Dims3 dims = {7, 5, 3}, Vec3d spacing = {0.3, 0.7, 1.9},
                   Vec3d origin = {-12.5, 3.25, 100.125}) {
  Volume v(dims, spacing, t);
  v.origin = origin;
  std::mt19937 rng(1234);
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    switch (t) {
      case ScalarType::UInt8: v.data[i] = static_cast<float>(rng() % 256); break;
      case ScalarType::Int8: v.data[i] = static_cast<float>(static_cast<int>(rng() % 256) - 128); break;
      case ScalarType::Int16: v.data[i] = static_cast<float>(static_cast<int>(rng() % 65536) - 32768); break;
      case ScalarType::UInt16: v.data[i] = static_cast<float>(rng() % 65536); break;
      case ScalarType::Int32:
      case ScalarType::Int64: v.data[i] = static_cast<float>(static_cast<int>(rng() % 2000001) - 1000000); break;
      case ScalarType::UInt32:
      case ScalarType::UInt64: v.data[i] = static_cast<float>(rng() % 2000001); break;
      default: v.data[i] = std::ldexp(static_cast<float>(rng() % 2000001) - 1e6f, -7); break;
    }
  }
  // Pin the type's extremes so clamping bugs show.
  if (scalar_type_is_integer(t) && scalar_type_size(t) <= 2) {
    v.data[0] = static_cast<float>(scalar_type_min(t));
    v.data[1] = static_cast<float>(scalar_type_max(t));
  }
  return v;
}

void expect_same_volume(const Volume& got, const Volume& want, double geom_tol = 1e-12) {
  EXPECT_EQ(got.dims, want.dims);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(got.spacing[i], want.spacing[i], geom_tol) << "spacing axis " << i;
    EXPECT_NEAR(got.origin[i], want.origin[i], geom_tol) << "origin axis " << i;
  }
  EXPECT_EQ(got.source_type, want.source_type);
  ASSERT_EQ(got.data.size(), want.data.size());
  for (std::size_t i = 0; i < got.data.size(); ++i) {
    ASSERT_EQ(got.data[i], want.data[i]) << "first difference at sample " << i;
  }
}


struct NrrdDeleter {
  void operator()(Nrrd* n) const { nrrdNix(n); }
};
struct IoStateDeleter {
  void operator()(NrrdIoState* s) const { nrrdIoStateNix(s); }
};

// Writes `v` (as uint16) with Teem itself, in the given encoding, so the
// reader is checked against files it did not write.
void teem_save(const std::string& path, Volume v, const NrrdEncoding* encoding, bool detached = false) {
  std::vector<std::uint16_t> samples(v.data.begin(), v.data.end());
  std::unique_ptr<Nrrd, NrrdDeleter> n(nrrdNew());
  std::unique_ptr<NrrdIoState, IoStateDeleter> nio(nrrdIoStateNew());
  ASSERT_EQ(nrrdWrap_va(n.get(), samples.data(), nrrdTypeUShort, 3u, v.dims[0], v.dims[1], v.dims[2]), 0);
  nrrdSpaceSet(n.get(), nrrdSpaceRightAnteriorSuperior);
  double dirs[3][NRRD_SPACE_DIM_MAX];
  for (int a = 0; a < 3; ++a) {
    nrrdSpaceVecSetNaN(dirs[a]);
    for (int c = 0; c < 3; ++c) dirs[a][c] = a == c ? v.spacing[a] : 0.0;
  }
  nrrdAxisInfoSet_va(n.get(), nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
  double origin[NRRD_SPACE_DIM_MAX];
  nrrdSpaceVecSetNaN(origin);
  for (int c = 0; c < 3; ++c) origin[c] = v.origin[c];
  ASSERT_EQ(nrrdSpaceOriginSet(n.get(), origin), 0);
  nrrdIoStateEncodingSet(nio.get(), encoding);
  if (detached) nrrdIoStateSet(nio.get(), nrrdIoStateDetachedHeader, AIR_TRUE);
  if (nrrdSave(path.c_str(), n.get(), nio.get()) != 0) {
    char* err = biffGetDone(NRRD);
    ADD_FAILURE() << "nrrdSave: " << err;
    std::free(err);
  }
}


// ---- scalar types ----------------------------------------------------------------

TEST(IoScalarType, NamesSizesAndRanges) {
  EXPECT_STREQ(scalar_type_name(ScalarType::UInt8), "uint8");
  EXPECT_STREQ(scalar_type_name(ScalarType::Float32), "float");
  EXPECT_STREQ(scalar_type_name(ScalarType::Float64), "double");
  EXPECT_EQ(scalar_type_size(ScalarType::Int16), 2u);
  EXPECT_EQ(scalar_type_size(ScalarType::UInt64), 8u);
  EXPECT_TRUE(scalar_type_is_integer(ScalarType::Int32));
  EXPECT_FALSE(scalar_type_is_integer(ScalarType::Float64));
  EXPECT_EQ(parse_scalar_type("uint16"), ScalarType::UInt16);
  EXPECT_EQ(parse_scalar_type("float32"), ScalarType::Float32);
  EXPECT_EQ(parse_scalar_type("float64"), ScalarType::Float64);
  EXPECT_EQ(parse_scalar_type("double"), ScalarType::Float64);
  EXPECT_FALSE(parse_scalar_type("uint12"));
  EXPECT_FALSE(parse_scalar_type(""));
  EXPECT_EQ(scalar_type_min(ScalarType::Int8), -128.0);
  EXPECT_EQ(scalar_type_max(ScalarType::UInt16), 65535.0);
  EXPECT_EQ(scalar_type_min(ScalarType::Int16), -32768.0);
  EXPECT_GT(scalar_type_max(ScalarType::Float32), 3e38);
  // Every name parses back to its type.
  for (ScalarType t : {ScalarType::Int8, ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16,
                       ScalarType::Int32, ScalarType::UInt32, ScalarType::Int64, ScalarType::UInt64,
                       ScalarType::Float32, ScalarType::Float64}) {
    EXPECT_EQ(parse_scalar_type(scalar_type_name(t)), t) << scalar_type_name(t);
  }
}

// ---- intensity map ------------------------------------------------------------------

TEST(IoIntensityMap, IntegerTypesUseTheTypeRange) {
  Volume v({2, 2, 2}, {1, 1, 1}, ScalarType::UInt8);
  v.data = {0, 10, 20, 30, 40, 50, 60, 70};  // the data range must not matter
  const IntensityMap m = v.intensity_map();
  EXPECT_EQ(m.lo, 0.0);
  EXPECT_EQ(m.hi, 255.0);
  EXPECT_FALSE(m.clamp);
  EXPECT_DOUBLE_EQ(m.to_unit(255), 1.0);
  EXPECT_DOUBLE_EQ(m.to_unit(51), 0.2);
  EXPECT_DOUBLE_EQ(m.from_unit(0.2), 51.0);
  EXPECT_NE(m.describe().find("type range [0, 255]"), std::string::npos) << m.describe();

  v.source_type = ScalarType::Int16;
  const IntensityMap s = v.intensity_map();
  EXPECT_EQ(s.lo, -32768.0);
  EXPECT_EQ(s.hi, 32767.0);
  EXPECT_DOUBLE_EQ(s.to_unit(-32768), 0.0);
  EXPECT_DOUBLE_EQ(s.to_unit(32767), 1.0);
}

TEST(IoIntensityMap, FloatTypesUseRobustPercentilesAndClamp) {
  Volume v({10, 10, 10}, {1, 1, 1}, ScalarType::Float32);
  for (std::size_t i = 0; i < 1000; ++i) v.data[i] = static_cast<float>(i);
  // Shuffle: the result must not depend on order.
  std::shuffle(v.data.begin(), v.data.end(), std::mt19937(7));
  const IntensityMap m = v.intensity_map();
  // Linear interpolation between order statistics at p * (n - 1).
  EXPECT_NEAR(m.lo, 0.005 * 999, 1e-3);
  EXPECT_NEAR(m.hi, 0.995 * 999, 1e-3);
  EXPECT_TRUE(m.clamp);
  EXPECT_DOUBLE_EQ(m.to_unit(-100), 0.0);
  EXPECT_DOUBLE_EQ(m.to_unit(5000), 1.0);
  EXPECT_NEAR(m.to_unit(m.from_unit(0.25)), 0.25, 1e-12);
  EXPECT_NE(m.describe().find("robust"), std::string::npos) << m.describe();
}

TEST(IoIntensityMap, ConstantFloatVolumeMapsToZero) {
  Volume v({3, 3, 3}, {1, 1, 1}, ScalarType::Float64);
  std::fill(v.data.begin(), v.data.end(), 42.0f);
  const IntensityMap m = v.intensity_map();
  EXPECT_EQ(m.lo, 42.0);
  EXPECT_EQ(m.hi, 42.0);
  EXPECT_EQ(m.to_unit(42.0), 0.0);
  EXPECT_EQ(m.to_unit(1e6), 0.0);
  EXPECT_FALSE(std::isnan(m.to_unit(-1e6)));
}

TEST(IoIntensityMap, NonFiniteSamplesAreIgnored) {
  Volume v({5, 1, 1}, {1, 1, 1}, ScalarType::Float32);
  v.data = {1.0f, NAN, 2.0f, INFINITY, 3.0f};
  const IntensityMap m = v.intensity_map();
  EXPECT_NEAR(m.lo, 1.01, 1e-9);
  EXPECT_NEAR(m.hi, 2.99, 1e-9);
}

// ---- statistics -------------------------------------------------------------------------

TEST(IoStats, KnownAnswers) {
  Volume v({2, 2, 2}, {1, 1, 1}, ScalarType::UInt8);
  v.data = {0, 0, 0, 0, 1, 2, 3, 10};
  const VolumeStats s = compute_stats(v, 2);
  EXPECT_EQ(s.min, 0.0);
  EXPECT_EQ(s.max, 10.0);
  EXPECT_DOUBLE_EQ(s.mean, 2.0);
  EXPECT_DOUBLE_EQ(s.stddev, std::sqrt(82.0 / 8.0));  // population std
  EXPECT_DOUBLE_EQ(s.zero_fraction, 0.5);
  ASSERT_EQ(s.histogram.size(), 2u);
  EXPECT_EQ(s.histogram[0], 7u);  // [0, 5)
  EXPECT_EQ(s.histogram[1], 1u);  // [5, 10], max in the last bin
  // Sorted: 0 0 0 0 1 2 3 10; p at position p/100 * 7, linear in between.
  EXPECT_NEAR(s.percentiles[3], 0.5, 1e-12);            // p50: between 0 and 1
  EXPECT_NEAR(s.percentiles[4], 2.25, 1e-12);           // p75: 5.25 -> 2 + 0.25
  EXPECT_NEAR(s.percentiles[6], 3.0 + 0.93 * 7, 1e-9);  // p99: 6.93
}

TEST(IoStats, PercentilesOfARampAreExact) {
  Volume v({101, 1, 1}, {1, 1, 1}, ScalarType::Float32);
  for (std::size_t i = 0; i <= 100; ++i) v.data[i] = static_cast<float>(100 - i);
  const VolumeStats s = compute_stats(v);
  const double want[7] = {1, 5, 25, 50, 75, 95, 99};
  for (int i = 0; i < 7; ++i) EXPECT_NEAR(s.percentiles[i], want[i], 1e-9) << i;
  ASSERT_EQ(s.histogram.size(), 16u);
  std::size_t total = 0;
  for (std::size_t c : s.histogram) total += c;
  EXPECT_EQ(total, 101u);
  EXPECT_DOUBLE_EQ(s.zero_fraction, 1.0 / 101.0);
}

TEST(IoStats, ConstantVolumeGoesToTheFirstBin) {
  Volume v({4, 4, 4}, {1, 1, 1}, ScalarType::UInt8);
  std::fill(v.data.begin(), v.data.end(), 7.0f);
  const VolumeStats s = compute_stats(v, 8);
  EXPECT_EQ(s.histogram[0], 64u);
  EXPECT_EQ(s.stddev, 0.0);
  EXPECT_EQ(s.percentiles[0], 7.0);
}

TEST(IoDescribe, MentionsGeometryTypeAndHistogram) {
  Volume v({4, 5, 6}, {0.5, 0.25, 2.0}, ScalarType::UInt8);
  v.origin = {1.5, -2, 3};
  for (std::size_t i = 0; i < v.data.size(); ++i) v.data[i] = i % 4 == 0 ? 0.0f : static_cast<float>(i % 200);
  const std::string d = describe_volume(v, "some/vol.nrrd");
  for (const char* part : {"some/vol.nrrd", "4 x 5 x 6", "120 voxels", "0.5 x 0.25 x 2 mm", "(1.5, -2, 3)",
                           "2 x 1.25 x 12 mm", "uint8", "type range [0, 255]", "p50=", "#"}) {
    EXPECT_NE(d.find(part), std::string::npos) << "'" << part << "' missing from:\n" << d;
  }
  EXPECT_NE(d.find("voxels equal to 0:  25.0 %"), std::string::npos) << d;
  EXPECT_NE(d.find("unscanned?"), std::string::npos) << d;
  // 16 histogram lines, each with a bar; the biggest bin has the longest bar.
  std::size_t bars = 0;
  std::istringstream in(d);
  for (std::string line; std::getline(in, line);) bars += line.rfind("  [", 0) == 0;
  EXPECT_EQ(bars, 16u);

  std::fill(v.data.begin(), v.data.end(), 3.0f);
  EXPECT_EQ(describe_volume(v, "x").find("unscanned?"), std::string::npos);
}

// ---- option parsing ------------------------------------------------------------------------

TEST(IoParse, DimsAndVectors) {
  EXPECT_EQ(parse_dims("17,23,9", "--raw"), (Dims3{17, 23, 9}));
  EXPECT_EQ(parse_dims(" 1, 2 ,3 ", "--raw"), (Dims3{1, 2, 3}));
  const Vec3d s = parse_vec3("0.5,1e-1,2", "--spacing");
  EXPECT_DOUBLE_EQ(s[0], 0.5);
  EXPECT_DOUBLE_EQ(s[1], 0.1);
  EXPECT_DOUBLE_EQ(s[2], 2.0);
  for (const char* bad : {"abc", "1,2", "1,2,3,4", "0,1,1", "-1,2,3", "1.5,2,3", "1,,3", "", "1,2,x",
                          "99999999999999999999999,1,1"}) {
    test::expect_input_error([&] { parse_dims(bad, "--raw"); },
                       {"--raw: expected X,Y,Z with positive integers, got '" + std::string(bad) + "'"});
  }
  for (const char* bad : {"abc", "1,2", "0,1,1", "-1,2,3", "nan,1,1", "inf,1,1", "1e999,1,1", "1;2;3"}) {
    test::expect_input_error([&] { parse_vec3(bad, "--spacing"); }, {"--spacing:", bad});
  }
}

// ---- round trips ---------------------------------------------------------------------------

struct RoundTripCase {
  const char* ext;
  bool compress;
  ScalarType type;
};

std::string case_name(const ::testing::TestParamInfo<RoundTripCase>& info) {
  std::string n = std::string(info.param.ext + 1) + (info.param.compress ? "_z_" : "_") +
                  scalar_type_name(info.param.type);
  return n;
}

class IoRoundTrip : public ::testing::TestWithParam<RoundTripCase> {};

TEST_P(IoRoundTrip, ReadBackEqualsWritten) {
  const RoundTripCase c = GetParam();
  ScratchDir dir;
  const Volume v = test_volume(c.type);
  const std::string path = dir.file(std::string("vol") + c.ext);
  WriteOptions opt;
  opt.compress = c.compress;
  write_volume(path, v, opt);
  const Volume back = read_volume(path);
  expect_same_volume(back, v);

  // Only the expected files exist: no temp files left behind.
  std::vector<std::string> want{std::string("vol") + c.ext};
  if (std::string(c.ext) == ".mhd") want.push_back(c.compress ? "vol.zraw" : "vol.raw");
  std::sort(want.begin(), want.end());
  EXPECT_EQ(dir.listing(), want);
}

std::vector<RoundTripCase> round_trip_cases() {
  std::vector<RoundTripCase> cases;
  for (const char* ext : {".nrrd", ".mha", ".mhd"})
    for (bool z : {false, true})
      for (ScalarType t : {ScalarType::UInt8, ScalarType::Int16, ScalarType::UInt16, ScalarType::Float32,
                           ScalarType::Float64, ScalarType::Int8, ScalarType::Int32})
        cases.push_back({ext, z, t});
  return cases;
}

INSTANTIATE_TEST_SUITE_P(IoFormats, IoRoundTrip, ::testing::ValuesIn(round_trip_cases()), case_name);

TEST(IoWrite, NrrdHeaderCarriesSpaceDirectionsAndOrigin) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::UInt8, {3, 4, 5}, {0.5, 0.25, 2}, {-1.5, 2, 30});
  write_volume(dir.file("v.nrrd"), v);
  const std::string text = read_bytes(dir.file("v.nrrd"));
  EXPECT_NE(text.find("space: left-posterior-superior"), std::string::npos) << text.substr(0, 400);
  EXPECT_NE(text.find("space directions: (0.5,0,0) (0,0.25,0) (0,0,2)"), std::string::npos);
  EXPECT_NE(text.find("space origin: (-1.5,2,30)"), std::string::npos);
  EXPECT_NE(text.find("encoding: raw"), std::string::npos);
  WriteOptions z;
  z.compress = true;
  write_volume(dir.file("v.nrrd"), v, z);  // overwrites in place
  EXPECT_NE(read_bytes(dir.file("v.nrrd")).find("encoding: gzip"), std::string::npos);
  expect_same_volume(read_volume(dir.file("v.nrrd")), v);
}

TEST(IoWrite, MetaImageHeaderKeys) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::Int16, {3, 4, 5}, {0.5, 0.25, 2}, {-1.5, 2, 30});
  WriteOptions z;
  z.compress = true;
  write_volume(dir.file("v.mhd"), v, z);
  const std::string text = read_bytes(dir.file("v.mhd"));
  for (const char* line : {"ObjectType = Image\n", "NDims = 3\n", "BinaryData = True\n",
                           "BinaryDataByteOrderMSB = False\n", "CompressedData = True\n", "CompressedDataSize = ",
                           "TransformMatrix = 1 0 0 0 1 0 0 0 1\n", "Offset = -1.5 2 30\n",
                           "ElementSpacing = 0.5 0.25 2\n", "DimSize = 3 4 5\n", "ElementType = MET_SHORT\n"}) {
    EXPECT_NE(text.find(line), std::string::npos) << line << " missing from\n" << text;
  }
  // ElementDataFile is the last line.
  EXPECT_EQ(text.substr(text.rfind("ElementDataFile")), "ElementDataFile = v.zraw\n");
}

TEST(IoWrite, OutputTypeRoundsAndClamps) {
  ScratchDir dir;
  Volume v({8, 1, 1}, {1, 1, 1}, ScalarType::Float32);
  v.data = {-5.0f, 0.4f, 0.6f, 1.5f, 254.6f, 300.0f, NAN, 127.49f};
  WriteOptions u8;
  u8.type = ScalarType::UInt8;
  for (const char* ext : {".nrrd", ".mha"}) {
    const std::string path = dir.file(std::string("u8") + ext);
    write_volume(path, v, u8);
    const Volume back = read_volume(path);
    EXPECT_EQ(back.source_type, ScalarType::UInt8);
    EXPECT_EQ(back.data, (std::vector<float>{0, 0, 1, 2, 255, 255, 0, 127})) << ext;
  }
  v.data = {-40000.0f, 40000.0f, -1.6f, 2.5f, 0, 0, 0, 0};
  WriteOptions s16;
  s16.type = ScalarType::Int16;
  write_volume(dir.file("s16.mha"), v, s16);
  const Volume back = read_volume(dir.file("s16.mha"));
  EXPECT_EQ(back.data[0], -32768.0f);
  EXPECT_EQ(back.data[1], 32767.0f);
  EXPECT_EQ(back.data[2], -2.0f);
  EXPECT_EQ(back.data[3], 3.0f);
}

TEST(IoWrite, UnsupportedExtensionAndUnwritablePlace) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::UInt8);
  test::expect_input_error([&] { write_volume(dir.file("out.xyz"), v); },
                     {"out.xyz", "unsupported output extension '.xyz' (use .nrrd, .mha, .mhd, .nii, .nii.gz or .vti)"});
  test::expect_input_error([&] { write_volume(dir.file("no/such/dir/out.nrrd"), v); },
                     {"out.nrrd", "No such file or directory"});
  fs::create_directory(dir.file("sub.nrrd"));
  test::expect_input_error([&] { write_volume(dir.file("sub.nrrd"), v); }, {"sub.nrrd", "Is a directory"});
  EXPECT_EQ(dir.listing(), std::vector<std::string>{"sub.nrrd"});
}

TEST(IoWrite, AtomicFileLeavesNothingBehindOnFailure) {
  ScratchDir dir;
  const std::string target = dir.file("out.nrrd");
  write_bytes(target, "old contents");
  try {
    io_detail::AtomicFile f(target);
    f.write("partial", 7);
    throw std::runtime_error("simulated failure mid-write");
  } catch (const std::runtime_error&) {
  }
  EXPECT_EQ(read_bytes(target), "old contents");
  EXPECT_EQ(dir.listing(), std::vector<std::string>{"out.nrrd"});

  {
    io_detail::AtomicFile f(target);
    f.write("new", 3);
    f.commit();
  }
  EXPECT_EQ(read_bytes(target), "new");
  EXPECT_EQ(dir.listing(), std::vector<std::string>{"out.nrrd"});
}

// ---- NRRD files written by Teem ------------------------------------------------------------

class IoNrrdEncoding : public ::testing::TestWithParam<std::string> {};

TEST_P(IoNrrdEncoding, ReadsWhatTeemWrites) {
  const std::string name = GetParam();
  const NrrdEncoding* enc = name == "raw"     ? nrrdEncodingRaw
                            : name == "gzip"  ? nrrdEncodingGzip
                            : name == "bzip2" ? nrrdEncodingBzip2
                            : name == "ascii" ? nrrdEncodingAscii
                                              : nrrdEncodingHex;
  ASSERT_TRUE(enc->available()) << name << " not compiled into Teem";
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::UInt16, {9, 4, 3}, {0.5, 0.75, 2.5}, {10, -20, 30.5});
  teem_save(dir.file("t.nrrd"), v, enc);
  std::string text = read_bytes(dir.file("t.nrrd"));
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return std::tolower(c); });
  EXPECT_NE(text.find("encoding: " + name), std::string::npos);  // Teem writes "ASCII"
  expect_same_volume(read_volume(dir.file("t.nrrd")), v);
}

INSTANTIATE_TEST_SUITE_P(IoTeem, IoNrrdEncoding, ::testing::Values("raw", "gzip", "bzip2", "ascii", "hex"));

TEST(IoNrrd, DetachedHeaderWrittenByTeem) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::UInt16, {6, 5, 4}, {0.4, 0.4, 1.2}, {1, 2, 3});
  teem_save(dir.file("d.nhdr"), v, nrrdEncodingRaw, true);
  EXPECT_EQ(dir.listing(), (std::vector<std::string>{"d.nhdr", "d.raw"}));
  expect_same_volume(read_volume(dir.file("d.nhdr")), v);
  // The reader resolves the data file relative to the header, not the cwd.
  EXPECT_NE(read_bytes(dir.file("d.nhdr")).find("data file: d.raw"), std::string::npos);
}

TEST(IoNrrd, HandWrittenHeadersSpacingsAxisMinsAndBigEndian) {
  ScratchDir dir;
  const std::vector<std::int16_t> s{1, -2, 300, -400, 5, 6, 7, 8};
  // Old-style "spacings" and "axis mins", big-endian data.
  write_bytes(dir.file("a.nrrd"),
              "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nspacings: 0.5 -0.75 2\n"
              "axis mins: 10 20 30\nendian: big\nencoding: raw\n\n" + as_bytes(s, true));
  const Volume a = read_volume(dir.file("a.nrrd"));
  EXPECT_EQ(a.source_type, ScalarType::Int16);
  EXPECT_EQ(a.spacing, (Vec3d{0.5, 0.75, 2}));
  EXPECT_EQ(a.origin, (Vec3d{10, 20, 30}));
  EXPECT_EQ(a.data, (std::vector<float>{1, -2, 300, -400, 5, 6, 7, 8}));

  // No spacing information at all: 1 mm, origin 0; a file named .bin still
  // reads as NRRD by its magic.
  write_bytes(dir.file("b.bin"), "NRRD0001\ntype: float\ndimension: 3\nsizes: 2 2 2\nencoding: ascii\n\n"
                                 "1 2 3 4\n5 6 7 8.5\n");
  const Volume b = read_volume(dir.file("b.bin"));
  EXPECT_EQ(b.spacing, (Vec3d{1, 1, 1}));
  EXPECT_EQ(b.origin, (Vec3d{0, 0, 0}));
  EXPECT_EQ(b.data.back(), 8.5f);

  // Non-diagonal space directions: spacing is the length of each direction.
  write_bytes(dir.file("c.nrrd"),
              "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nspace: left-posterior-superior\n"
              "space directions: (0,0.6,0.8) (2,0,0) (0,0,-3)\nspace origin: (1,2,3)\nencoding: raw\n\n"
              "\x05\x06");
  const Volume c = read_volume(dir.file("c.nrrd"));
  EXPECT_NEAR(c.spacing[0], 1.0, 1e-12);
  EXPECT_NEAR(c.spacing[1], 2.0, 1e-12);
  EXPECT_NEAR(c.spacing[2], 3.0, 1e-12);
  EXPECT_EQ(c.origin, (Vec3d{1, 2, 3}));
}

TEST(IoNrrd, ErrorsAreOneLineAndNameTheFile) {
  ScratchDir dir;
  const auto nrrd = [&](const std::string& name, const std::string& text) {
    write_bytes(dir.file(name), text);
    return dir.file(name);
  };
  const std::string trunc = nrrd("trunc.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 4 4\n"
                                               "endian: little\nencoding: raw\n\nabc");
  test::expect_input_error([&] { read_volume(trunc); }, {trunc + ": ", "truncated"});
  const std::string gz = nrrd("trunc_gz.nrrd", "NRRD0004\ntype: uint16\ndimension: 3\nsizes: 4 4 4\n"
                                               "endian: little\nencoding: gzip\n\nabc");
  test::expect_input_error([&] { read_volume(gz); }, {gz + ": "});
  const std::string d2 = nrrd("d2.nrrd", "NRRD0004\ntype: uint8\ndimension: 2\nsizes: 4 5\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(d2); }, {d2 + ": expected a 3-D scalar volume, found 2-D data (sizes 4 5)"});
  // 4-D: a sequence of frames when the last axis is a list (or time, domain, no kind), else refused.
  const std::string d4 = nrrd("d4.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 4 5 6\n"
                                         "kinds: domain domain domain vector\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(d4); },
                     {"found 4-D data (sizes 3 4 5 6) whose last axis (kind vector) is not a list of frames"});
  const std::string s4 = nrrd("s4.nrrd", "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 4 5 6\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(s4); }, {"data truncated: expected 360 bytes of raw data"});
  const std::string block = nrrd("block.nrrd", "NRRD0004\ntype: block\nblock size: 4\ndimension: 3\n"
                                               "sizes: 2 2 2\nendian: little\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(block); }, {block + ": unsupported NRRD type 'block'"});
  const std::string ovf = nrrd("ovf.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\n"
                                           "sizes: 4294967296 4294967296 4294967296\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(ovf); },
                     {ovf + ": sizes 4294967296 4294967296 4294967296 overflow the voxel count"});
  const std::string ovf2 = nrrd("ovf2.nrrd", "NRRD0004\ntype: float\ndimension: 3\n"
                                             "sizes: 2000000 2000000 2000000\nendian: little\nencoding: raw\n\n");
  test::expect_input_error([&] { read_volume(ovf2); }, {ovf2 + ": ", "overflow"});
  const std::string big = nrrd("big.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\n"
                                           "sizes: 100000 100000 1000\nencoding: raw\n\nabc");
  test::expect_input_error([&] { read_volume(big); }, {big + ": ", "memory"});
  const std::string garbage = nrrd("garbage.nrrd", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2\n");
  test::expect_input_error([&] { read_volume(garbage); }, {garbage + ": "});
  const std::string missing = nrrd("det.nhdr", "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\n"
                                               "data file: nothere.raw\nencoding: raw\n");
  test::expect_input_error([&] { read_volume(missing); }, {missing + ": ", "nothere.raw"});
}

// ---- MetaImage files written by hand ----------------------------------------------------------

TEST(IoMetaImage, ToleratesWhitespaceUnknownKeysAndCrLf) {
  ScratchDir dir;
  const std::vector<std::uint16_t> s{1, 2, 3, 4, 5, 6, 7, 65535};
  write_bytes(dir.file("a.mha"),
              "ObjectType = Image\r\nNDims =    3\r\nAnatomicalOrientation = RAI\r\n"
              "CenterOfRotation = 0 0 0\r\nKinds = domain domain            domain\r\n"
              "UltrasoundImageOrientation = MFA\r\nSeq_Frame0000_ImageStatus = OK\r\n"
              "BinaryData = True\r\n  ElementByteOrderMSB = True  \r\n\r\n"
              "DimSize = 2 2                2\r\nElementNumberOfChannels = 1\r\n"
              "ElementSize = 0.5 0.25 4\r\nPosition = -1 -2 -3.5\r\n"
              "TransformMatrix = 0 1 0 1 0 0 0 0 1\r\nElementType = MET_USHORT\r\n"
              "ElementDataFile = LOCAL\r\n" + as_bytes(s, true));
  const Volume a = read_volume(dir.file("a.mha"));
  EXPECT_EQ(a.dims, (Dims3{2, 2, 2}));
  EXPECT_EQ(a.source_type, ScalarType::UInt16);
  EXPECT_EQ(a.spacing, (Vec3d{0.5, 0.25, 4}));
  EXPECT_EQ(a.origin, (Vec3d{-1, -2, -3.5}));
  EXPECT_EQ(a.data, std::vector<float>(s.begin(), s.end()));
}

TEST(IoMetaImage, LongIsInt32AndTrailingBytesAreIgnored) {
  ScratchDir dir;
  const std::vector<std::int32_t> s{-1, 2, -3, 4, 100000, 6, 7, 8};
  write_bytes(dir.file("l.mha"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_LONG\nElementSpacing = 1 1 1\n"
                                 "Origin = 5 6 7\nElementDataFile = LOCAL\n" + as_bytes(s) + "extra");
  const Volume l = read_volume(dir.file("l.mha"));
  EXPECT_EQ(l.source_type, ScalarType::Int32);
  EXPECT_EQ(l.origin, (Vec3d{5, 6, 7}));
  EXPECT_EQ(l.data, std::vector<float>(s.begin(), s.end()));
}

TEST(IoMetaImage, DetachedDataFiles) {
  ScratchDir dir;
  const std::vector<float> s{1.5f, 2, 3, 4, 5, 6, 7, -8.25f};
  fs::create_directory(dir.file("data"));
  write_bytes(dir.file("data/s.raw"), as_bytes(s));
  write_bytes(dir.file("h.mhd"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\n"
                                 "ElementDataFile = data/s.raw\n");
  EXPECT_EQ(read_volume(dir.file("h.mhd")).data, s);

  // HeaderSize = -1: the samples are the last bytes of the file.
  write_bytes(dir.file("data/p.raw"), "some preamble" + as_bytes(s));
  write_bytes(dir.file("p.mhd"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\nHeaderSize = -1\n"
                                 "ElementDataFile = data/p.raw\n");
  EXPECT_EQ(read_volume(dir.file("p.mhd")).data, s);
  write_bytes(dir.file("q.mhd"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\nHeaderSize = 13\n"
                                 "ElementDataFile = data/p.raw\n");
  EXPECT_EQ(read_volume(dir.file("q.mhd")).data, s);

  // Wrong size without HeaderSize.
  write_bytes(dir.file("data/w.raw"), as_bytes(s) + "x");
  write_bytes(dir.file("w.mhd"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\nElementDataFile = data/w.raw\n");
  test::expect_input_error([&] { read_volume(dir.file("w.mhd")); },
                     {dir.file("w.mhd") + ": data file data/w.raw has 33 bytes, expected 32"});
  write_bytes(dir.file("m.mhd"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_FLOAT\nElementDataFile = gone.raw\n");
  test::expect_input_error([&] { read_volume(dir.file("m.mhd")); }, {"m.mhd: data file ", "gone.raw", "No such file"});
}

TEST(IoMetaImage, CompressedWithoutCompressedDataSize) {
  ScratchDir dir;
  const std::vector<std::uint8_t> s{9, 8, 7, 6, 5, 4, 3, 2};
  std::vector<unsigned char> packed(compressBound(s.size()));
  uLongf len = packed.size();
  ASSERT_EQ(compress2(packed.data(), &len, s.data(), s.size(), 9), Z_OK);
  write_bytes(dir.file("c.mha"), "NDims = 3\nDimSize = 2 2 2\nElementType = MET_UCHAR\nCompressedData = True\n"
                                 "ElementDataFile = LOCAL\n" +
                                     std::string(reinterpret_cast<char*>(packed.data()), len));
  EXPECT_EQ(read_volume(dir.file("c.mha")).data, std::vector<float>(s.begin(), s.end()));
}

TEST(IoMetaImage, ErrorsAreOneLineAndNameTheFile) {
  ScratchDir dir;
  const auto mha = [&](const std::string& name, const std::string& text) {
    write_bytes(dir.file(name), text);
    return dir.file(name);
  };
  const std::string head = "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\n";
  const std::string t = mha("t.mha", head + "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  test::expect_input_error([&] { read_volume(t); }, {t + ": data truncated: expected 64 bytes, found 3"});
  const std::string foo = mha("foo.mha", head + "ElementType = MET_FOO\nElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(foo); }, {foo + ": unknown ElementType MET_FOO"});
  const std::string d2 = mha("d2.mha", "NDims = 2\nDimSize = 4 4\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(d2); }, {d2 + ": expected a 3-D scalar volume, found 2-D data (DimSize 4 4)"});
  const std::string rgb = mha("rgb.mha", head + "ElementNumberOfChannels = 3\nElementType = MET_UCHAR\n"
                                                "ElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(rgb); }, {rgb + ": ElementNumberOfChannels = 3"});
  const std::string list = mha("list.mhd", head + "ElementType = MET_UCHAR\nElementDataFile = LIST\na.raw\n");
  test::expect_input_error([&] { read_volume(list); }, {list + ": ElementDataFile LIST/pattern not supported"});
  const std::string pat = mha("pat.mhd", head + "ElementType = MET_UCHAR\nElementDataFile = s%03d.raw 1 4 1\n");
  test::expect_input_error([&] { read_volume(pat); }, {"ElementDataFile LIST/pattern not supported"});
  const std::string ovf = mha("ovf.mha", "NDims = 3\nDimSize = 4294967296 4294967296 4294967296\n"
                                         "ElementType = MET_UCHAR\nElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(ovf); }, {ovf + ": dims 4294967296x4294967296x4294967296 overflow"});
  const std::string big = mha("big.mha", "NDims = 3\nDimSize = 100000 100000 1000\n"
                                         "ElementType = MET_UCHAR\nElementDataFile = LOCAL\nabc");
  test::expect_input_error([&] { read_volume(big); }, {big + ": ", "memory"});
  const std::string noend = mha("noend.mha", head + "ElementType = MET_UCHAR\n");
  test::expect_input_error([&] { read_volume(noend); }, {noend + ": ", "ElementDataFile"});
  const std::string bad = mha("bad.mha", "NDims = 3\nthis line has no equals sign\n");
  test::expect_input_error([&] { read_volume(bad); }, {bad + ": malformed header line 2"});
  const std::string nodims = mha("nodims.mha", "NDims = 3\nElementType = MET_UCHAR\nElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(nodims); }, {nodims + ": missing DimSize"});
  const std::string corrupt = mha("corrupt.mha", head + "ElementType = MET_UCHAR\nCompressedData = True\n"
                                                        "ElementDataFile = LOCAL\nthis is not zlib data");
  test::expect_input_error([&] { read_volume(corrupt); }, {corrupt + ": corrupt compressed data"});
  const std::string spacing = mha("sp.mha", head + "ElementSpacing = 1 x 1\nElementType = MET_UCHAR\n"
                                                   "ElementDataFile = LOCAL\n");
  test::expect_input_error([&] { read_volume(spacing); }, {spacing + ": ElementSpacing"});
}

TEST(IoMetaImage, CompressedTruncationIsReported) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::Float32, {20, 20, 20});
  WriteOptions z;
  z.compress = true;
  write_volume(dir.file("z.mha"), v, z);
  const std::string full = read_bytes(dir.file("z.mha"));
  // With CompressedDataSize the reader notices before inflating.
  write_bytes(dir.file("cut.mha"), full.substr(0, full.size() - 100));
  test::expect_input_error([&] { read_volume(dir.file("cut.mha")); }, {"cut.mha: compressed data truncated"});
  // Without it, inflate runs out of input.
  std::string nosize = full.substr(0, full.size() - 100);
  const auto a = nosize.find("CompressedDataSize");
  nosize.erase(a, nosize.find('\n', a) + 1 - a);
  write_bytes(dir.file("cut2.mha"), nosize);
  test::expect_input_error([&] { read_volume(dir.file("cut2.mha")); }, {"cut2.mha: data truncated"});
}

// ---- raw -------------------------------------------------------------------------------------

TEST(IoRaw, LittleAndBigEndian) {
  ScratchDir dir;
  const std::vector<std::uint16_t> s{1, 256, 2, 65535, 4, 5};
  write_bytes(dir.file("le.raw"), as_bytes(s));
  write_bytes(dir.file("be.raw"), as_bytes(s, true));
  RawSpec spec;
  spec.dims = {3, 2, 1};
  spec.type = ScalarType::UInt16;
  spec.spacing = {0.5, 1, 2};
  const Volume le = read_volume(dir.file("le.raw"), spec);
  EXPECT_EQ(le.data, std::vector<float>(s.begin(), s.end()));
  EXPECT_EQ(le.spacing, (Vec3d{0.5, 1, 2}));
  EXPECT_EQ(le.source_type, ScalarType::UInt16);
  spec.big_endian = true;
  EXPECT_EQ(read_volume(dir.file("be.raw"), spec).data, std::vector<float>(s.begin(), s.end()));

  const std::vector<double> d{1.25, -2, 3e10, 0};
  write_bytes(dir.file("d.dat"), as_bytes(d, true));
  RawSpec ds{{2, 2, 1}, ScalarType::Float64, {1, 1, 1}, true};
  const Volume dv = read_volume(dir.file("d.dat"), ds);
  EXPECT_EQ(dv.data, (std::vector<float>{1.25f, -2.0f, 3e10f, 0.0f}));
}

TEST(IoRaw, SizeMustMatchExactly) {
  ScratchDir dir;
  write_bytes(dir.file("v.raw"), std::string(100, '\0'));
  RawSpec spec{{17, 23, 9}, ScalarType::UInt16, {1, 1, 1}, false};
  test::expect_input_error([&] { read_volume(dir.file("v.raw"), spec); },
                     {dir.file("v.raw") + ": file has 100 bytes, but 17x23x9 uint16 needs 7038 bytes"});
}

// ---- dispatch and paths -----------------------------------------------------------------------

TEST(IoDispatch, UnreadablePathsAndUnknownFormats) {
  ScratchDir dir;
  test::expect_input_error([&] { read_volume(dir.file("nope.nrrd")); },
                     {dir.file("nope.nrrd") + ": cannot open: No such file or directory"});
  test::expect_input_error([&] { read_volume(dir.path()); },
                           {dir.path() + (dicom_supported() ? ": a folder with no DICOM image in it" : ": cannot open: Is a directory")});
  RawSpec spec{{1, 1, 1}, ScalarType::UInt8, {1, 1, 1}, false};
  test::expect_input_error([&] { read_volume(dir.file("nope.raw"), spec); }, {"nope.raw: cannot open: No such file"});
  write_bytes(dir.file("v.xyz"), "hello");
  test::expect_input_error([&] { read_volume(dir.file("v.xyz")); },
                     {dir.file("v.xyz") +
                      ": unrecognised format (expected .nrrd, .nhdr, .mha, .mhd, .nii, .nii.gz, .hdr, .vti, .vol (Kretz), DICOM (.dcm or a series folder), or --raw X,Y,Z --type T)"});
  write_bytes(dir.file("empty.mha"), "");
  test::expect_input_error([&] { read_volume(dir.file("empty.mha")); }, {"empty.mha: "});
  // Extensions are matched case-insensitively.
  write_volume(dir.file("UP.MHA"), test_volume(ScalarType::UInt8));
  EXPECT_EQ(read_volume(dir.file("UP.MHA")).dims, (Dims3{7, 5, 3}));
}

TEST(IoDispatch, EnsureDistinctOutput) {
  ScratchDir dir;
  write_bytes(dir.file("in.nrrd"), "x");
  const std::string msg = ": output would overwrite the input file";
  test::expect_input_error([&] { ensure_distinct_output(dir.file("in.nrrd"), dir.file("in.nrrd")); },
                     {dir.file("in.nrrd") + msg});
  // Another spelling of the same file, a hard link and a symlink.
  const std::string other = dir.path() + "/./sub/../in.nrrd";
  fs::create_directory(dir.file("sub"));
  test::expect_input_error([&] { ensure_distinct_output(dir.file("in.nrrd"), other); }, {msg});
  fs::create_hard_link(dir.file("in.nrrd"), dir.file("hard.nrrd"));
  test::expect_input_error([&] { ensure_distinct_output(dir.file("in.nrrd"), dir.file("hard.nrrd")); }, {msg});
  fs::create_symlink(dir.file("in.nrrd"), dir.file("link.nrrd"));
  test::expect_input_error([&] { ensure_distinct_output(dir.file("link.nrrd"), dir.file("in.nrrd")); }, {msg});
  // A .mhd output writes <stem>.raw, which must not be the input either.
  write_bytes(dir.file("vol.raw"), "x");
  test::expect_input_error([&] { ensure_distinct_output(dir.file("vol.raw"), dir.file("vol.mhd")); },
                     {"vol.mhd: output's data file", "would overwrite the input file"});
  EXPECT_NO_THROW(ensure_distinct_output(dir.file("in.nrrd"), dir.file("out.nrrd")));
  EXPECT_NO_THROW(ensure_distinct_output(dir.file("in.nrrd"), dir.file("in.mha")));
  EXPECT_NO_THROW(ensure_distinct_output(dir.file("a.nrrd"), dir.file("b.nrrd")));  // neither exists
}

TEST(IoMemory, FitsInMemory) {
  EXPECT_TRUE(fits_in_memory(64 * 64 * 64, 4));
  EXPECT_FALSE(fits_in_memory(std::size_t(100000) * 100000 * 1000, 5));
  EXPECT_FALSE(fits_in_memory(SIZE_MAX / 2, 4));  // the product overflows
}

// ---- real data --------------------------------------------------------------------------------

TEST(IoRealData, SpinePhantomFreehandReconstructed) {
  const std::string path = test::shared_data_dir() + "/plus-spine/SpinePhantomFreehandReconstructed.mha";
  REQUIRE_SHARED_FILE(path);
  const Volume v = read_volume(path);
  EXPECT_EQ(v.dims, (Dims3{147, 106, 104}));
  EXPECT_EQ(v.source_type, ScalarType::UInt8);
  EXPECT_EQ(v.spacing, (Vec3d{0.5, 0.5, 0.5}));
  EXPECT_DOUBLE_EQ(v.origin[0], -74.5217);
  EXPECT_DOUBLE_EQ(v.origin[1], 165.573);
  EXPECT_DOUBLE_EQ(v.origin[2], 29.072);
  const VolumeStats s = compute_stats(v);
  EXPECT_NEAR(s.zero_fraction, 0.71, 0.01);  // the unswept region
  EXPECT_GE(s.min, 0.0);
  EXPECT_LE(s.max, 255.0);
  EXPECT_GT(s.max, 200.0);  // the bright bone echo
}

TEST(IoRealData, VolumeReconstructorLnMeanCrop) {
  const std::string path = test::shared_data_dir() + "/plus-spine/vtkVolumeReconstructorTestLNMEANvolumeRef.mha";
  REQUIRE_SHARED_FILE(path);
  const Volume v = read_volume(path);
  EXPECT_EQ(v.dims, (Dims3{80, 93, 98}));
  EXPECT_EQ(v.source_type, ScalarType::UInt8);
  EXPECT_EQ(v.spacing, (Vec3d{0.5, 0.5, 0.5}));
  EXPECT_DOUBLE_EQ(v.origin[0], -57.0272);
  EXPECT_DOUBLE_EQ(v.origin[1], 168.545);
  EXPECT_DOUBLE_EQ(v.origin[2], 30.5384);
  EXPECT_GT(compute_stats(v).max, 100.0);
}

TEST(IoRealData, SpinePhantomSurvivesEveryFormat) {
  const std::string path = test::shared_data_dir() + "/plus-spine/SpinePhantomFreehandReconstructed.mha";
  REQUIRE_SHARED_FILE(path);
  const Volume v = read_volume(path);
  ScratchDir dir;
  for (const char* name : {"s.nrrd", "s.mha", "s.mhd"}) {
    for (bool z : {false, true}) {
      WriteOptions opt;
      opt.compress = z;
      write_volume(dir.file(name), v, opt);
      expect_same_volume(read_volume(dir.file(name)), v);
    }
  }
}

// ---- garbled input ------------------------------------------------------------------------------

// Every prefix and many random byte edits of valid files must either read
// or fail with a one-line InputError: never crash, hang or throw anything else.
TEST(IoFuzz, GarbledAndTruncatedFilesFailCleanly) {
  ScratchDir dir;
  const Volume v = test_volume(ScalarType::Int16, {5, 4, 3});
  std::vector<std::pair<std::string, std::string>> seeds;  // name, bytes
  for (const char* name : {"f.mha", "f.nrrd"}) {
    for (bool z : {false, true}) {
      WriteOptions opt;
      opt.compress = z;
      write_volume(dir.file(name), v, opt);
      seeds.emplace_back(name, read_bytes(dir.file(name)));
    }
  }
  std::mt19937 rng(99);
  std::string junk = "0123456789 =-.:\n\r\tabcxyzMET_ \xff";
  junk.push_back('\0');
  std::size_t ok = 0, failed = 0;
  const auto attempt = [&](const std::string& name, const std::string& bytes) {
    const std::string path = dir.file("g_" + name);
    write_bytes(path, bytes);
    try {
      const Volume r = read_volume(path);
      EXPECT_EQ(r.data.size(), r.voxels());
      ++ok;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
      EXPECT_EQ(msg.rfind(path + ": ", 0), 0u) << msg;
      ++failed;
    }
  };
  for (const auto& [name, bytes] : seeds) {
    for (std::size_t len = 0; len < bytes.size(); len += 1 + len / 16) attempt(name, bytes.substr(0, len));
    const std::size_t header_len = std::min<std::size_t>(bytes.size(), 400);
    for (int i = 0; i < 300; ++i) {
      std::string b = bytes;
      const int edits = 1 + static_cast<int>(rng() % 3);
      for (int e = 0; e < edits; ++e) b[rng() % header_len] = junk[rng() % junk.size()];
      attempt(name, b);
    }
  }
  EXPECT_GT(failed, 0u);
  EXPECT_GT(ok, 0u);
}

}  // namespace
}  // namespace softshell
