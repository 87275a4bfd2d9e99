// VTK XML ImageData (.vti) reading, hand-written: the file is small XML around one scalar point
// array, whose samples are ascii text, inline base64 ("binary") or appended (raw bytes or
// base64) after the XML, uncompressed or in vtkZLibDataCompressor blocks. VTK's own reader would
// bring all of VTK into the core for ~300 lines of parsing; see docs/formats.md, ".vti".
//
// The XML is scanned, not parsed in full: tags and their attributes up to <AppendedData>,
// whose bytes are binary. Every size is checked against the bytes present before anything of
// that size is allocated.
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstring>
#include <map>
#include <optional>
#include <sstream>

#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::io_detail {

namespace {

constexpr std::uint64_t kMaxInflateRatio = 1032;  // deflate's largest expansion

std::string shown(const std::string& s, std::size_t max = 40) {
  std::string out;
  for (char c : s.substr(0, max)) out += (static_cast<unsigned char>(c) >= 0x20 && c != 0x7f) ? c : '?';
  return out + (s.size() > max ? "..." : "");
}

struct Tag {
  std::string name;  // "DataArray", "/DataArray", ...
  std::map<std::string, std::string> attrs;
  std::size_t begin = 0, end = 0;  // '<' and one past '>'
};

// The next tag at or after `pos` in text[0, limit); nullopt when none. Comments, processing
// instructions and declarations are skipped.
std::optional<Tag> next_tag(const std::string& path, const std::string& text, std::size_t pos, std::size_t limit) {
  while (true) {
    const std::size_t lt = text.find('<', pos);
    if (lt == std::string::npos || lt >= limit) return std::nullopt;
    if (text.compare(lt, 4, "<!--") == 0) {
      const std::size_t e = text.find("-->", lt + 4);
      if (e == std::string::npos || e >= limit) throw input_error(path, "unterminated XML comment");
      pos = e + 3;
      continue;
    }
    const std::size_t gt = text.find('>', lt);
    if (gt == std::string::npos || gt >= limit) throw input_error(path, "unterminated XML tag");
    if (text[lt + 1] == '?' || text[lt + 1] == '!') {
      pos = gt + 1;
      continue;
    }
    Tag t;
    t.begin = lt;
    t.end = gt + 1;
    std::size_t i = lt + 1;
    while (i < gt && !std::isspace(static_cast<unsigned char>(text[i])) && text[i] != '/') ++i;
    if (text[lt + 1] == '/') {
      i = lt + 2;
      while (i < gt && !std::isspace(static_cast<unsigned char>(text[i]))) ++i;
    }
    t.name = text.substr(lt + 1, i - lt - 1);
    // name="value" pairs.
    while (i < gt) {
      while (i < gt && (std::isspace(static_cast<unsigned char>(text[i])) || text[i] == '/')) ++i;
      if (i >= gt) break;
      const std::size_t eq = text.find('=', i);
      if (eq == std::string::npos || eq >= gt) throw input_error(path, "malformed XML attribute in <" + shown(t.name) + ">");
      const std::string key = trim(text.substr(i, eq - i));
      std::size_t q = eq + 1;
      while (q < gt && std::isspace(static_cast<unsigned char>(text[q]))) ++q;
      if (q >= gt || (text[q] != '"' && text[q] != '\'')) throw input_error(path, "unquoted XML attribute '" + shown(key) + "'");
      const std::size_t close = text.find(text[q], q + 1);
      if (close == std::string::npos || close >= gt) throw input_error(path, "unterminated XML attribute '" + shown(key) + "'");
      t.attrs[key] = text.substr(q + 1, close - q - 1);
      i = close + 1;
    }
    return t;
  }
}

std::vector<double> numbers(const std::string& path, const std::string& what, const std::string& text, std::size_t n) {
  std::istringstream in(text);
  std::vector<double> out;
  std::string w;
  while (in >> w) {
    errno = 0;
    char* end = nullptr;
    const double x = std::strtod(w.c_str(), &end);
    if (errno == ERANGE || *end != '\0' || !std::isfinite(x))
      throw input_error(path, what + "=\"" + shown(text) + "\": '" + shown(w) + "' is not a number");
    out.push_back(x);
  }
  if (out.size() != n)
    throw input_error(path, what + "=\"" + shown(text) + "\": expected " + std::to_string(n) + " numbers");
  return out;
}

std::optional<ScalarType> vtk_type(const std::string& t) {
  static const std::pair<const char*, ScalarType> kTypes[] = {
      {"Int8", ScalarType::Int8},     {"UInt8", ScalarType::UInt8},     {"Int16", ScalarType::Int16},
      {"UInt16", ScalarType::UInt16}, {"Int32", ScalarType::Int32},     {"UInt32", ScalarType::UInt32},
      {"Int64", ScalarType::Int64},   {"UInt64", ScalarType::UInt64},   {"Float32", ScalarType::Float32},
      {"Float64", ScalarType::Float64}, {"Char", ScalarType::Int8},     {"UnsignedChar", ScalarType::UInt8}};
  for (const auto& [name, type] : kTypes)
    if (t == name) return type;
  return std::nullopt;
}

// Base64 with whitespace skipped; padding may end one encoded block and another begin
// (VTK encodes a compressed array's header and data separately). Stops after `max` bytes.
std::string base64_decode(const std::string& path, const char* p, std::size_t n, std::size_t max) {
  static const auto table = [] {
    std::array<int, 256> t{};
    t.fill(-1);
    const char* a = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for (int i = 0; i < 64; ++i) t[static_cast<unsigned char>(a[i])] = i;
    return t;
  }();
  std::string out;
  int quad[4], k = 0, pad = 0;
  for (std::size_t i = 0; i < n && out.size() < max; ++i) {
    const unsigned char c = static_cast<unsigned char>(p[i]);
    if (std::isspace(c)) continue;
    if (c == '<') break;  // the end of the element (</DataArray>, </AppendedData>)
    if (c == '=') {
      quad[k++] = 0, ++pad;
    } else {
      if (table[c] < 0) throw input_error(path, "invalid base64 data (character " + std::to_string(int(c)) + ")");
      if (pad) throw input_error(path, "invalid base64 data (text after padding inside a group)");
      quad[k++] = table[c];
    }
    if (k == 4) {
      const unsigned v = (unsigned(quad[0]) << 18) | (unsigned(quad[1]) << 12) | (unsigned(quad[2]) << 6) | unsigned(quad[3]);
      const char b[3] = {char(v >> 16), char(v >> 8), char(v)};
      out.append(b, static_cast<std::size_t>(3 - std::min(pad, 2)));
      k = pad = 0;
    }
  }
  if (out.size() > max) out.resize(max);
  return out;
}

struct VtiInfo {
  VolumeHeader header;
  bool big_endian = false;
  int header_bytes = 4;  // UInt32 or UInt64 block headers
  bool compressed = false;
  std::string format;  // ascii, binary, appended
  std::size_t content_begin = 0, content_end = 0;  // DataArray's text (ascii / binary)
  std::size_t appended = std::string::npos;        // first byte after '_'
  bool appended_base64 = false;
  std::uint64_t offset = 0;
  std::string text;  // the whole file
};

std::uint64_t get_uint(const std::string& b, std::size_t at, int bytes, bool big) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) {
    const std::uint64_t byte = static_cast<unsigned char>(b[at + (big ? std::size_t(i) : std::size_t(bytes - 1 - i))]);
    v = (v << 8) | byte;
  }
  return v;
}

VtiInfo open_vti(const std::string& path) {
  VtiInfo v;
  {
    FilePtr f = open_for_reading(path);
    const std::uint64_t size = file_size(f.get());
    if (size > SIZE_MAX || !fits_in_memory(static_cast<std::size_t>(size), 2))
      throw input_error(path, "file of " + std::to_string(size) + " bytes does not fit in memory");
    v.text.resize(static_cast<std::size_t>(size));
    v.text.resize(read_up_to(f.get(), v.text.data(), v.text.size(), path));
  }
  const std::string& t = v.text;
  // The XML ends where appended binary data begins.
  std::size_t limit = t.size();
  const std::size_t app = t.find("<AppendedData");
  if (app != std::string::npos) limit = app;

  std::optional<Tag> file, image, piece, array;
  bool in_point_data = false, cell_array = false;
  std::string scalars_name;
  int pieces = 0;
  for (std::size_t pos = 0;;) {
    const auto tag = next_tag(path, t, pos, limit);
    if (!tag) break;
    pos = tag->end;
    if (tag->name == "VTKFile") file = tag;
    else if (tag->name == "ImageData") image = tag;
    else if (tag->name == "Piece") ++pieces, piece = tag;
    else if (tag->name == "PointData") {
      in_point_data = t[tag->end - 2] != '/';
      if (tag->attrs.count("Scalars")) scalars_name = tag->attrs.at("Scalars");
    } else if (tag->name == "/PointData") in_point_data = false;
    else if (tag->name == "DataArray") {
      if (!in_point_data) {
        cell_array = true;
        continue;
      }
      const bool pick = !array || (!scalars_name.empty() && tag->attrs.count("Name") && tag->attrs.at("Name") == scalars_name &&
                                   !(array->attrs.count("Name") && array->attrs.at("Name") == scalars_name));
      if (pick) {
        array = tag;
        const std::size_t close = t.find("</DataArray>", tag->end);
        const bool empty_element = t[tag->end - 2] == '/';
        v.content_begin = tag->end;
        v.content_end = empty_element ? tag->end : (close == std::string::npos || close > limit ? limit : close);
      }
    }
  }
  if (!file || file->attrs["type"] != "ImageData")
    throw input_error(path, file ? "a VTK " + shown(file->attrs["type"]) + " file; softshell reads ImageData (.vti)"
                                 : "not a VTK XML file (no <VTKFile>)");
  if (!image) throw input_error(path, "no <ImageData> element");
  if (pieces != 1) throw input_error(path, std::to_string(pieces) + " pieces; softshell reads a .vti of one piece");
  if (!array)
    throw input_error(path, cell_array ? "cell data only; softshell reads point data (one sample per grid point)"
                                       : "no point data array");

  auto attr = [](const Tag& tag, const char* k, const std::string& def = "") {
    const auto it = tag.attrs.find(k);
    return it == tag.attrs.end() ? def : it->second;
  };
  const std::string order = attr(*file, "byte_order", "LittleEndian");
  if (order != "LittleEndian" && order != "BigEndian") throw input_error(path, "byte_order \"" + shown(order) + "\"");
  v.big_endian = order == "BigEndian";
  const std::string htype = attr(*file, "header_type", "UInt32");
  if (htype != "UInt32" && htype != "UInt64") throw input_error(path, "header_type \"" + shown(htype) + "\"");
  v.header_bytes = htype == "UInt64" ? 8 : 4;
  const std::string comp = attr(*file, "compressor");
  if (!comp.empty() && comp != "vtkZLibDataCompressor")
    throw input_error(path, "compressor " + shown(comp) + " is not supported (uncompressed or vtkZLibDataCompressor)");
  v.compressed = !comp.empty();

  // Geometry: the piece's extent (the whole extent when it has none).
  const std::string extent_text = attr(*piece, "Extent", attr(*image, "WholeExtent"));
  const auto ext = numbers(path, "Extent", extent_text, 6);
  VolumeHeader& h = v.header;
  Vec3d start{};
  for (int a = 0; a < 3; ++a) {
    if (ext[2 * a] != std::floor(ext[2 * a]) || ext[2 * a + 1] != std::floor(ext[2 * a + 1]) || ext[2 * a + 1] < ext[2 * a] ||
        ext[2 * a + 1] - ext[2 * a] >= 1e12)
      throw input_error(path, "Extent=\"" + shown(extent_text) + "\": expected three integer ranges lo <= hi");
    h.dims[a] = static_cast<std::size_t>(ext[2 * a + 1] - ext[2 * a] + 1);
    start[a] = ext[2 * a];
  }
  const auto sp = numbers(path, "Spacing", attr(*image, "Spacing", "1 1 1"), 3);
  const auto org = numbers(path, "Origin", attr(*image, "Origin", "0 0 0"), 3);
  const auto dir = numbers(path, "Direction", attr(*image, "Direction", "1 0 0 0 1 0 0 0 1"), 9);
  // VTK: point (i, j, k) of the extent at Origin + Direction * (Spacing .* (i, j, k)), Direction
  // written row by row; axis a is its column a. A negative spacing flips the axis.
  Mat3 axes{};
  for (int a = 0; a < 3; ++a) {
    const double s = sp[a] < 0 ? -1.0 : 1.0;
    double len = 0;
    for (int c = 0; c < 3; ++c) axes[a][c] = s * dir[3 * c + a], len += axes[a][c] * axes[a][c];
    len = std::sqrt(len);
    for (int c = 0; c < 3 && len > 0; ++c) axes[a][c] = std::fabs(len - 1.0) <= 1e-12 ? axes[a][c] : axes[a][c] / len;
    h.spacing[a] = sp[a] != 0.0 ? std::fabs(sp[a]) : 1.0;
  }
  if (!(std::fabs(determinant(axes)) > 1e-6)) axes = kIdentityAxes;
  h.frame.axes = axes;
  for (int c = 0; c < 3; ++c) {
    h.origin[c] = org[c];
    for (int a = 0; a < 3; ++a) h.origin[c] += start[a] * h.spacing[a] * axes[a][c];
  }
  check_geometry(path, h.spacing, h.origin);

  const std::string type_name = attr(*array, "type");
  const auto type = vtk_type(type_name);
  if (!type) throw input_error(path, "DataArray type \"" + shown(type_name) + "\" is not a scalar number type");
  h.type = *type;
  const std::string comps = attr(*array, "NumberOfComponents", "1");
  if (comps != "1")
    throw input_error(path, "DataArray \"" + shown(attr(*array, "Name")) + "\" has " + shown(comps) +
                                " components; softshell reads a scalar volume (1 component)");
  v.format = attr(*array, "format", "ascii");
  if (v.format != "ascii" && v.format != "binary" && v.format != "appended")
    throw input_error(path, "DataArray format \"" + shown(v.format) + "\" (expected ascii, binary or appended)");
  if (v.format == "appended") {
    if (app == std::string::npos) throw input_error(path, "appended data array but no <AppendedData>");
    const auto atag = next_tag(path, t, app, t.size());
    if (!atag) throw input_error(path, "unterminated <AppendedData> tag");
    const std::string enc = atag->attrs.count("encoding") ? atag->attrs.at("encoding") : "raw";
    if (enc != "raw" && enc != "base64") throw input_error(path, "AppendedData encoding \"" + shown(enc) + "\"");
    v.appended_base64 = enc == "base64";
    const std::size_t underscore = t.find('_', atag->end);
    if (underscore == std::string::npos) throw input_error(path, "<AppendedData> without its '_' marker");
    v.appended = underscore + 1;
    const std::string off = attr(*array, "offset", "0");
    errno = 0;
    char* end = nullptr;
    const unsigned long long o = std::strtoull(off.c_str(), &end, 10);
    if (off.empty() || *end != '\0' || errno == ERANGE || off[0] == '-') throw input_error(path, "offset=\"" + shown(off) + "\"");
    v.offset = o;
    // Compared without adding: an offset near 2^64 wrapped the sum past the check (found by fuzz_vti).
    if (v.appended > t.size() || v.offset > t.size() - v.appended)
      throw input_error(path, "data truncated: offset " + off + " lies past the end of the file");
  } else if (v.compressed && v.format == "ascii") {
    v.compressed = false;  // ascii arrays are never compressed
  }

  const std::size_t voxels = checked_voxels(path, h.dims, h.type);
  const std::uint64_t expected = std::uint64_t(voxels) * scalar_type_size(h.type);
  // What the file holds can be bounded before decoding anything.
  std::uint64_t avail = 0;
  if (v.format == "ascii") {
    avail = v.content_end - v.content_begin;
    if (avail + 1 < 2 * std::uint64_t(voxels))
      throw input_error(path, "data truncated: " + std::to_string(voxels) + " ascii samples need at least " +
                                  std::to_string(2 * voxels - 1) + " characters, found " + std::to_string(avail));
  } else {
    const bool b64 = v.format == "binary" || v.appended_base64;
    const std::uint64_t raw_avail = v.format == "binary" ? v.content_end - v.content_begin : t.size() - v.appended - v.offset;
    avail = b64 ? raw_avail / 4 * 3 : raw_avail;
    const std::uint64_t cap = v.compressed ? kMaxInflateRatio * avail + 1024 : avail;
    if (cap < expected)
      throw input_error(path, "data truncated: " + std::to_string(avail) + " bytes of " +
                                  (v.compressed ? "compressed " : "") + "data cannot hold the " + std::to_string(expected) +
                                  " bytes the extent declares");
  }
  h.files = {path};
  return v;
}

// The samples' bytes of a binary or appended array (block header(s) removed, inflated).
std::string array_bytes(const std::string& path, const VtiInfo& v, std::uint64_t expected) {
  const std::string& t = v.text;
  const int hb = v.header_bytes;
  const bool b64 = v.format == "binary" || v.appended_base64;
  const char* p = v.format == "binary" ? t.data() + v.content_begin : t.data() + v.appended + v.offset;
  const std::size_t n = v.format == "binary" ? v.content_end - v.content_begin : t.size() - v.appended - v.offset;
  // Enough of the stream for the header(s) and the data, decoded once.
  const std::string block = b64 ? base64_decode(path, p, n, SIZE_MAX) : std::string(p, n);
  if (!v.compressed) {
    if (block.size() < std::size_t(hb)) throw input_error(path, "data truncated: no block header");
    const std::uint64_t nbytes = get_uint(block, 0, hb, v.big_endian);
    if (nbytes < expected || block.size() - hb < expected)
      throw input_error(path, "data truncated: expected " + std::to_string(expected) + " bytes, the array holds " +
                                  std::to_string(std::min<std::uint64_t>(nbytes, block.size() - hb)));
    return block.substr(hb, expected);
  }
  // vtkZLibDataCompressor: [blocks][block size][last block size][compressed size x blocks], then the blocks.
  if (block.size() < std::size_t(3 * hb)) throw input_error(path, "data truncated: no compression header");
  const std::uint64_t nblocks = get_uint(block, 0, hb, v.big_endian), bsize = get_uint(block, hb, hb, v.big_endian),
                      last = get_uint(block, 2 * hb, hb, v.big_endian);
  if (nblocks == 0 || nblocks > block.size() || bsize == 0 || bsize > (std::uint64_t(1) << 32))
    throw input_error(path, "corrupt compression header (" + std::to_string(nblocks) + " blocks of " + std::to_string(bsize) + " bytes)");
  const std::uint64_t total = (nblocks - 1) * bsize + (last ? last : bsize);
  if (total < expected)
    throw input_error(path, "data truncated: the compressed array holds " + std::to_string(total) + " bytes, expected " +
                                std::to_string(expected));
  std::size_t at = std::size_t(3 + nblocks) * hb;
  if (block.size() < at) throw input_error(path, "data truncated: compression header");
  std::string out;
  out.reserve(static_cast<std::size_t>(expected));
  for (std::uint64_t b = 0; b < nblocks && out.size() < expected; ++b) {
    const std::uint64_t csize = get_uint(block, std::size_t(3 + b) * hb, hb, v.big_endian);
    const std::uint64_t usize = (b + 1 == nblocks && last) ? last : bsize;
    if (csize > block.size() - at) throw input_error(path, "data truncated: compressed block " + std::to_string(b));
    if (usize > kMaxInflateRatio * csize + 1024)
      throw input_error(path, "corrupt compression header: block " + std::to_string(b) + " of " + std::to_string(csize) +
                                  " bytes cannot inflate to " + std::to_string(usize));
    // Only what the extent still needs is inflated (a header may promise more).
    const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(usize, expected - out.size()));
    if (want > UINT_MAX) throw input_error(path, "compressed block " + std::to_string(b) + " larger than 4 GiB");
    const std::size_t old = out.size();
    out.resize(old + want);
    z_stream zs{};
    if (inflateInit(&zs) != Z_OK) throw input_error(path, "zlib initialisation failed");
    zs.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(block.data() + at));
    zs.avail_in = static_cast<uInt>(std::min<std::uint64_t>(csize, UINT_MAX));
    zs.next_out = reinterpret_cast<Bytef*>(out.data() + old);
    zs.avail_out = static_cast<uInt>(want);
    const int rc = inflate(&zs, Z_FINISH);
    const std::size_t got = want - zs.avail_out;
    inflateEnd(&zs);
    if ((rc != Z_STREAM_END && rc != Z_BUF_ERROR && rc != Z_OK) || got != want)
      throw input_error(path, "corrupt compressed block " + std::to_string(b) + " (zlib error " + std::to_string(rc) + ")");
    at += static_cast<std::size_t>(csize);
  }
  if (out.size() < expected) throw input_error(path, "data truncated after decompression");
  out.resize(static_cast<std::size_t>(expected));
  return out;
}

}  // namespace

VolumeHeader read_vti_header(const std::string& path) { return open_vti(path).header; }

Volume read_vti(const std::string& path) {
  VtiInfo v = open_vti(path);
  const VolumeHeader& h = v.header;
  Volume out(h.dims, h.spacing, h.type);
  out.origin = h.origin;
  out.frame = h.frame;
  const std::size_t n = out.voxels();
  if (v.format == "ascii") {
    const char* p = v.text.data() + v.content_begin;
    const char* e = v.text.data() + v.content_end;
    std::size_t i = 0;
    std::string word;
    while (p < e && i < n) {
      while (p < e && std::isspace(static_cast<unsigned char>(*p))) ++p;
      const char* w = p;
      while (p < e && !std::isspace(static_cast<unsigned char>(*p))) ++p;
      if (w == p) break;
      word.assign(w, p);
      char* end = nullptr;
      const double x = std::strtod(word.c_str(), &end);
      if (*end != '\0') throw input_error(path, "ascii sample " + std::to_string(i) + " '" + shown(word) + "' is not a number");
      out.data[i++] = static_cast<float>(x);
    }
    if (i < n) throw input_error(path, "data truncated: expected " + std::to_string(n) + " ascii samples, found " + std::to_string(i));
  } else {
    const std::uint64_t expected = std::uint64_t(n) * scalar_type_size(h.type);
    const std::string bytes = array_bytes(path, v, expected);
    decode_samples(reinterpret_cast<const unsigned char*>(bytes.data()), n, h.type, v.big_endian != host_is_big_endian(),
                   out.data.data());
  }
  return out;
}

// ---- writing -------------------------------------------------------------------

namespace {

const char* vtk_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return "Int8";
    case ScalarType::UInt8: return "UInt8";
    case ScalarType::Int16: return "Int16";
    case ScalarType::UInt16: return "UInt16";
    case ScalarType::Int32: return "Int32";
    case ScalarType::UInt32: return "UInt32";
    case ScalarType::Int64: return "Int64";
    case ScalarType::UInt64: return "UInt64";
    case ScalarType::Float32: return "Float32";
    case ScalarType::Float64: return "Float64";
  }
  return "Float32";
}

void put_uint64(std::string& out, std::uint64_t x) {
  for (int b = 0; b < 8; ++b) out.push_back(static_cast<char>((x >> (8 * b)) & 0xff));
}

}  // namespace

void write_vti(const std::string& path, const Volume& v, const WriteOptions& opt) {
  const ScalarType type = opt.type.value_or(v.source_type);
  std::vector<unsigned char> samples = encode_samples(v.data, type);
  const std::size_t elem = scalar_type_size(type);
  if (host_is_big_endian())
    for (std::size_t i = 0; i + elem <= samples.size(); i += elem) std::reverse(&samples[i], &samples[i] + elem);
  // VTK has no anatomical frame; softshell writes ITK's LPS (a RAS or LAS
  // volume converted, the same physical placement), as for MetaImage.
  Vec3d origin = v.origin;
  const WorldFrame frame = v.frame.to_lps(origin);
  std::ostringstream x;
  x.precision(17);
  const std::string extent = "0 " + std::to_string(v.dims[0] - 1) + " 0 " + std::to_string(v.dims[1] - 1) + " 0 " +
                             std::to_string(v.dims[2] - 1);
  x << "<?xml version=\"1.0\"?>\n"
    << "<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\""
    << (opt.compress ? " compressor=\"vtkZLibDataCompressor\"" : "") << ">\n"
    << "  <ImageData WholeExtent=\"" << extent << "\" Origin=\"" << origin[0] << ' ' << origin[1] << ' ' << origin[2]
    << "\" Spacing=\"" << v.spacing[0] << ' ' << v.spacing[1] << ' ' << v.spacing[2] << "\" Direction=\"";
  // Row by row: entry (row c, column a) is component c of axis a.
  for (int c = 0; c < 3; ++c)
    for (int a = 0; a < 3; ++a) x << (c + a ? " " : "") << frame.axes[a][c] + 0.0;
  x << "\">\n"
    << "    <Piece Extent=\"" << extent << "\">\n"
    << "      <PointData Scalars=\"scalars\">\n"
    << "        <DataArray type=\"" << vtk_type_name(type) << "\" Name=\"scalars\" format=\"appended\" offset=\"0\"/>\n"
    << "      </PointData>\n"
    << "      <CellData/>\n"
    << "    </Piece>\n"
    << "  </ImageData>\n"
    << "  <AppendedData encoding=\"raw\">\n   _";
  std::string body = x.str();
  if (!opt.compress) {
    put_uint64(body, samples.size());
    body.append(reinterpret_cast<const char*>(samples.data()), samples.size());
  } else {
    // vtkZLibDataCompressor: a header of block count, block size, last
    // block's size and each block's compressed size, then the zlib blocks.
    constexpr std::size_t kBlock = std::size_t(1) << 20;
    const std::size_t blocks = std::max<std::size_t>(1, (samples.size() + kBlock - 1) / kBlock);
    std::vector<std::string> packed(blocks);
    for (std::size_t b = 0; b < blocks; ++b) {
      const std::size_t begin = b * kBlock, n = std::min(kBlock, samples.size() - begin);
      uLongf len = compressBound(static_cast<uLong>(n));
      packed[b].resize(len);
      if (compress2(reinterpret_cast<Bytef*>(packed[b].data()), &len, samples.data() + begin, static_cast<uLong>(n),
                    Z_DEFAULT_COMPRESSION) != Z_OK)
        throw input_error(path, "cannot write: zlib compression failed");
      packed[b].resize(len);
    }
    put_uint64(body, blocks);
    put_uint64(body, kBlock);
    put_uint64(body, samples.size() - (blocks - 1) * kBlock);
    for (const std::string& p : packed) put_uint64(body, p.size());
    for (const std::string& p : packed) body += p;
  }
  body += "\n  </AppendedData>\n</VTKFile>\n";
  AtomicFile out(path);
  out.write(body.data(), body.size());
  out.commit();
}

}  // namespace softshell::io_detail
