// VTK XML ImageData input (host/io_vti.cpp, docs/formats.md ".vti"): ascii, inline base64,
// appended raw and base64 arrays, UInt32/UInt64 block headers, both byte orders, zlib
// compression (vtkZLibDataCompressor), the extent, spacing, origin and direction, and the
// bad-input answers. Every file is written by the test.
#include <gtest/gtest.h>
#include <zlib.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "cli_fixture.hpp"
#include "error.hpp"
#include "io.hpp"
#include "volume.hpp"

namespace softshell {
namespace {

using test::CliTest;
namespace fs = std::filesystem;

std::string b64(const std::string& in) {
  static const char* a = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (std::size_t i = 0; i < in.size(); i += 3) {
    unsigned v = static_cast<unsigned char>(in[i]) << 16;
    if (i + 1 < in.size()) v |= static_cast<unsigned char>(in[i + 1]) << 8;
    if (i + 2 < in.size()) v |= static_cast<unsigned char>(in[i + 2]);
    out += a[(v >> 18) & 63];
    out += a[(v >> 12) & 63];
    out += i + 1 < in.size() ? a[(v >> 6) & 63] : '=';
    out += i + 2 < in.size() ? a[v & 63] : '=';
  }
  return out;
}

template <class T>
std::string bytes_of(const std::vector<T>& v, bool big = false) {
  std::string s;
  for (const T& x : v) {
    std::string b(reinterpret_cast<const char*>(&x), sizeof(T));
    if (big) std::reverse(b.begin(), b.end());
    s += b;
  }
  return s;
}

std::string uint_bytes(std::uint64_t v, int n, bool big = false) {
  std::string s;
  for (int i = 0; i < n; ++i) s += char((v >> (8 * i)) & 0xff);
  if (big) std::reverse(s.begin(), s.end());
  return s;
}

// vtkZLibDataCompressor's layout: header [blocks, block size, last block size, sizes...], blocks.
std::pair<std::string, std::string> zlib_blocks(const std::string& data, std::size_t block, int hb) {
  std::vector<std::string> parts;
  for (std::size_t i = 0; i < data.size(); i += block) {
    const std::string piece = data.substr(i, block);
    uLongf n = compressBound(uLong(piece.size()));
    std::string c(n, '\0');
    compress(reinterpret_cast<Bytef*>(c.data()), &n, reinterpret_cast<const Bytef*>(piece.data()), uLong(piece.size()));
    c.resize(n);
    parts.push_back(c);
  }
  std::string header = uint_bytes(parts.size(), hb) + uint_bytes(block, hb) + uint_bytes(data.size() % block, hb);
  std::string body;
  for (const auto& p : parts) header += uint_bytes(p.size(), hb), body += p;
  return {header, body};
}

const char* kHead = "<?xml version=\"1.0\"?>\n<!-- written by a test -->\n";

std::string vti(const std::string& file_attrs, const std::string& image_attrs, const std::string& extent,
                const std::string& point_data, const std::string& appended = "") {
  return std::string(kHead) + "<VTKFile type=\"ImageData\" version=\"1.0\" " + file_attrs + ">\n  <ImageData " +
         image_attrs + ">\n    <Piece Extent=\"" + extent + "\">\n      " + point_data +
         "\n      <CellData>\n      </CellData>\n    </Piece>\n  </ImageData>\n" + appended + "</VTKFile>\n";
}

class Vti : public CliTest {};

TEST_F(Vti, AsciiWithExtentSpacingOriginAndDirection) {
  // Direction: rows of a rotation by 90 degrees about z (x -> y, y -> -x).
  const std::string f = vti("byte_order=\"LittleEndian\"",
                            "WholeExtent=\"1 3 0 1 2 3\" Origin=\"10 20 30\" Spacing=\"0.5 0.25 2\" "
                            "Direction=\"0 -1 0 1 0 0 0 0 1\"",
                            "1 3 0 1 2 3",
                            "<PointData Scalars=\"s\">\n<DataArray type=\"Float32\" Name=\"s\" format=\"ascii\">\n"
                            "0 1 2 3 4 5\n6 7 8 9 10 11.5\n</DataArray>\n</PointData>");
  write("a.vti", f);
  const Volume v = read_volume(file("a.vti"));
  EXPECT_EQ(v.dims, (Dims3{3, 2, 2}));
  EXPECT_EQ(v.source_type, ScalarType::Float32);
  EXPECT_EQ(v.spacing, (Vec3d{0.5, 0.25, 2}));
  EXPECT_EQ(v.frame.axes[0], (Vec3d{0, 1, 0}));   // column 0 of Direction
  EXPECT_EQ(v.frame.axes[1], (Vec3d{-1, 0, 0}));  // column 1
  // Voxel (0,0,0) is extent point (1, 0, 2): Origin + Direction * (Spacing .* (1, 0, 2)).
  EXPECT_EQ(v.origin, (Vec3d{10, 20 + 0.5, 30 + 4}));
  EXPECT_EQ(v.data.back(), 11.5f);
  EXPECT_EQ(v.data[4], 4.0f);
  EXPECT_EQ(v.frame.space, "");
  // Written as NRRD: the same world (LPS by convention), the same transform.
  write_volume(file("a.nrrd"), v);
  const Volume n = read_volume(file("a.nrrd"));
  for (const Vec3d p : {Vec3d{0, 0, 0}, Vec3d{2, 1, 1}}) {
    const Vec3d a = v.index_to_world(p), b = n.index_to_world(p);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], 1e-12);
  }
}

TEST_F(Vti, InlineBase64OneStreamOrTwo) {
  const std::vector<std::uint16_t> s{1, 2, 300, 4000, 5, 65535, 7, 8};
  const std::string data = bytes_of(s);
  for (bool two : {false, true}) {
    SCOPED_TRACE(two);
    const std::string header = uint_bytes(data.size(), 4);
    const std::string text = two ? b64(header) + b64(data) : b64(header + data);
    write("b.vti", vti("byte_order=\"LittleEndian\" header_type=\"UInt32\"", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 0 1 0 1",
                       "<PointData><DataArray type=\"UInt16\" Name=\"v\" format=\"binary\">\n  " + text +
                           "\n</DataArray></PointData>"));
    const Volume v = read_volume(file("b.vti"));
    EXPECT_EQ(v.source_type, ScalarType::UInt16);
    EXPECT_EQ(v.data, std::vector<float>(s.begin(), s.end()));
  }
}

TEST_F(Vti, AppendedRawAndBase64PickTheScalarsArray) {
  const std::vector<std::int16_t> first{9, 9, 9, 9, 9, 9, 9, 9}, second{-1, 2, -3, 4, -5, 6, -7, 8};
  for (bool big : {false, true})
    for (bool base64 : {false, true}) {
      SCOPED_TRACE(std::string(big ? "big" : "little") + (base64 ? " base64" : " raw"));
      const std::string b1 = uint_bytes(16, 8, big) + bytes_of(first, big), b2 = uint_bytes(16, 8, big) + bytes_of(second, big);
      const std::string e1 = base64 ? b64(b1) : b1, e2 = base64 ? b64(b2) : b2;
      const std::string arrays =
          "<PointData Scalars=\"second\">\n"
          "<DataArray type=\"Int16\" Name=\"first\" format=\"appended\" offset=\"0\"/>\n"
          "<DataArray type=\"Int16\" Name=\"second\" format=\"appended\" offset=\"" + std::to_string(e1.size()) + "\"/>\n"
          "</PointData>";
      const std::string app = std::string("<AppendedData encoding=\"") + (base64 ? "base64" : "raw") + "\">\n   _" + e1 + e2 +
                              "\n</AppendedData>\n";
      write("c.vti", vti(std::string("byte_order=\"") + (big ? "BigEndian" : "LittleEndian") + "\" header_type=\"UInt64\"",
                         "WholeExtent=\"0 1 0 1 0 1\" Origin=\"0 0 0\" Spacing=\"1 1 1\"", "0 1 0 1 0 1", arrays, app));
      const Volume v = read_volume(file("c.vti"));
      EXPECT_EQ(v.source_type, ScalarType::Int16);
      EXPECT_EQ(v.data, std::vector<float>(second.begin(), second.end()));
    }
}

TEST_F(Vti, ZlibCompressedArrays) {
  std::vector<float> s(3000);
  for (std::size_t i = 0; i < s.size(); ++i) s[i] = float(std::sin(0.01 * double(i)));
  const std::string data = bytes_of(s);
  const auto [header, body] = zlib_blocks(data, 4096, 4);  // three blocks, the last one short
  // Appended raw.
  write("z.vti", vti("byte_order=\"LittleEndian\" compressor=\"vtkZLibDataCompressor\"", "WholeExtent=\"0 29 0 9 0 9\"",
                     "0 29 0 9 0 9", "<PointData><DataArray type=\"Float32\" format=\"appended\" offset=\"0\"/></PointData>",
                     "<AppendedData encoding=\"raw\">_" + header + body + "</AppendedData>\n"));
  const Volume v = read_volume(file("z.vti"));
  EXPECT_EQ(v.dims, (Dims3{30, 10, 10}));
  EXPECT_EQ(v.data, s);
  // Inline binary: header and data encoded separately, as VTK writes them.
  write("zb.vti", vti("byte_order=\"LittleEndian\" compressor=\"vtkZLibDataCompressor\"", "WholeExtent=\"0 29 0 9 0 9\"",
                      "0 29 0 9 0 9", "<PointData><DataArray type=\"Float32\" format=\"binary\">" + b64(header) + b64(body) +
                                          "</DataArray></PointData>"));
  EXPECT_EQ(read_volume(file("zb.vti")).data, s);
  // A corrupt block.
  std::string bad = body;
  bad[bad.size() / 2] ^= 0x55;
  write("zbad.vti", vti("compressor=\"vtkZLibDataCompressor\"", "WholeExtent=\"0 29 0 9 0 9\"", "0 29 0 9 0 9",
                        "<PointData><DataArray type=\"Float32\" format=\"appended\" offset=\"0\"/></PointData>",
                        "<AppendedData encoding=\"raw\">_" + header + bad + "</AppendedData>\n"));
  info_fails(file("zbad.vti"), {"zbad.vti", "compressed block"});
}

TEST_F(Vti, BadInputGetsOneLineAndExit2) {
  const std::string ok_array = "<PointData><DataArray type=\"UInt8\" format=\"ascii\">1 2 3 4 5 6 7 8</DataArray></PointData>";
  write("poly.vti", std::string(kHead) + "<VTKFile type=\"PolyData\"><PolyData></PolyData></VTKFile>\n");
  info_fails(file("poly.vti"), {"PolyData", "ImageData"});
  write("none.vti", "hello, not XML\n");
  info_fails(file("none.vti"), {"not a VTK XML file"});
  write("short.vti", vti("", "WholeExtent=\"0 1 0 1 0 2\"", "0 1 0 1 0 2", ok_array));
  info_fails(file("short.vti"), {"data truncated"});
  write("rgb.vti", vti("", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 0 1 0 1",
                       "<PointData><DataArray type=\"UInt8\" NumberOfComponents=\"3\" format=\"ascii\">1</DataArray></PointData>"));
  info_fails(file("rgb.vti"), {"3 components", "scalar volume"});
  write("cells.vti", vti("", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 0 1 0 1",
                         "<PointData/><CellData><DataArray type=\"UInt8\" format=\"ascii\">1</DataArray></CellData>"));
  info_fails(file("cells.vti"), {"cell data only"});
  write("lz4.vti", vti("compressor=\"vtkLZ4DataCompressor\"", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 0 1 0 1", ok_array));
  info_fails(file("lz4.vti"), {"vtkLZ4DataCompressor", "not supported"});
  write("ext.vti", vti("", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 5 2 0 1", ok_array));
  info_fails(file("ext.vti"), {"Extent"});
  write("type.vti", vti("", "WholeExtent=\"0 1 0 1 0 1\"", "0 1 0 1 0 1",
                        "<PointData><DataArray type=\"String\" format=\"ascii\">a</DataArray></PointData>"));
  info_fails(file("type.vti"), {"String"});
  // An appended array whose block header promises more than the file holds.
  write("trunc.vti", vti("", "WholeExtent=\"0 9 0 9 0 9\"", "0 9 0 9 0 9",
                         "<PointData><DataArray type=\"UInt8\" format=\"appended\" offset=\"0\"/></PointData>",
                         "<AppendedData encoding=\"raw\">_" + uint_bytes(1000, 4) + std::string(100, 'x') + "</AppendedData>\n"));
  info_fails(file("trunc.vti"), {"data truncated"});
  // Nothing is written when classify meets one.
  const test::RunResult r = run({"classify", file("short.vti"), "--iso", "10", "-o", file("u.nrrd")});
  expect_one_line_error(r, {"data truncated"});
  EXPECT_FALSE(fs::exists(file("u.nrrd")));
}

// Found by fuzz_vti: a block header that promises 4 GiB from 32 compressed bytes.
TEST_F(Vti, ReproHugeBlockIsRefusedAtOnce) {
  const std::string repro = std::string(SOFTSHELL_SOURCE_DIR) + "/tests/data/repro/vti_zlib_last_block_4g.vti";
  write("huge.vti", test::slurp(repro));
  const test::RunResult r = run({"info", file("huge.vti")});
  expect_one_line_error(r, {"huge.vti", "corrupt compression header", "cannot inflate to 4294967294"});
  EXPECT_LT(r.max_rss_kb, 300 * 1024) << "the promised size was allocated";
}

TEST_F(Vti, ReproAppendedOffsetNear2To64IsPastTheEnd) {
  // Found by fuzz_vti: offset="...18446744073709551615" wrapped appended +
  // offset past the end-of-file check, and the reader formed a pointer
  // 2^64 - 1 bytes on (UBSan: pointer overflow).
  const std::string repro = std::string(SOFTSHELL_SOURCE_DIR) + "/tests/data/repro/vti_appended_offset_2e64.vti";
  write("offset.vti", test::slurp(repro));
  const test::RunResult r = run({"info", file("offset.vti")});
  expect_one_line_error(r, {"offset.vti", "data truncated", "lies past the end of the file"});
}

}  // namespace
}  // namespace softshell
