// MetaImage (.mha / .mhd) reading and writing, hand-written: the format is a
// "Key = Value" text header ending with ElementDataFile, followed by (LOCAL)
// or pointing to (detached) the samples, optionally zlib-compressed. Only
// 3-D single-channel images are accepted; see docs/formats.md.
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <sstream>

#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::io_detail {

namespace fs = std::filesystem;

namespace {

constexpr std::size_t kMaxHeaderLine = 64 * 1024;  // longer means it is not a header
constexpr int kMaxHeaderLines = 4096;

struct ElementTypeName {
  const char* name;
  ScalarType type;
};
// MET_LONG / MET_ULONG are 32-bit in MetaIO files written on every platform
// that matters (they mirror ITK's 32-bit "long" on Windows); 64-bit data uses
// MET_LONG_LONG.
constexpr ElementTypeName kElementTypes[] = {
    {"MET_CHAR", ScalarType::Int8},        {"MET_UCHAR", ScalarType::UInt8},
    {"MET_SHORT", ScalarType::Int16},      {"MET_USHORT", ScalarType::UInt16},
    {"MET_INT", ScalarType::Int32},        {"MET_UINT", ScalarType::UInt32},
    {"MET_LONG", ScalarType::Int32},       {"MET_ULONG", ScalarType::UInt32},
    {"MET_LONG_LONG", ScalarType::Int64},  {"MET_ULONG_LONG", ScalarType::UInt64},
    {"MET_FLOAT", ScalarType::Float32},    {"MET_DOUBLE", ScalarType::Float64},
};

const char* element_type_name(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return "MET_CHAR";
    case ScalarType::UInt8: return "MET_UCHAR";
    case ScalarType::Int16: return "MET_SHORT";
    case ScalarType::UInt16: return "MET_USHORT";
    case ScalarType::Int32: return "MET_INT";
    case ScalarType::UInt32: return "MET_UINT";
    case ScalarType::Int64: return "MET_LONG_LONG";
    case ScalarType::UInt64: return "MET_ULONG_LONG";
    case ScalarType::Float32: return "MET_FLOAT";
    case ScalarType::Float64: return "MET_DOUBLE";
  }
  return "MET_OTHER";
}

// Printable, length-limited excerpt of untrusted text for messages.
std::string excerpt(const std::string& s, std::size_t max = 40) {
  std::string out;
  for (char c : s.substr(0, max)) {
    out += (static_cast<unsigned char>(c) >= 0x20 && static_cast<unsigned char>(c) < 0x7f) ? c : '?';
  }
  if (s.size() > max) out += "...";
  return out;
}

std::string upper_ascii(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  return s;
}

std::vector<std::string> words(const std::string& s) {
  std::istringstream in(s);
  std::vector<std::string> out;
  std::string w;
  while (in >> w) out.push_back(w);
  return out;
}

// The parsed header. Values stay text until needed so unknown keys cost nothing.
struct Header {
  std::map<std::string, std::string> keys;
  std::string data_file;       // value of ElementDataFile
  std::uint64_t data_offset = 0;  // for LOCAL: where the samples start
};

class Parser {
 public:
  explicit Parser(std::string path) : path_(std::move(path)) {}

  [[noreturn]] void fail(const std::string& problem) const { throw input_error(path_, problem); }

  // Reads "Key = Value" lines up to and including ElementDataFile.
  Header read_header(std::FILE* f) {
    Header h;
    std::string line;
    for (int n = 1;; ++n) {
      if (n > kMaxHeaderLines) fail("no ElementDataFile line in the first " + std::to_string(kMaxHeaderLines) + " header lines");
      if (!read_line(f, line)) {
        fail(h.keys.empty() ? "empty file or not a MetaImage header"
                            : "header ends without an ElementDataFile line (it must be the last key)");
      }
      const std::string t = trim(line);
      if (t.empty()) continue;
      const auto eq = t.find('=');
      if (eq == std::string::npos || trim(t.substr(0, eq)).empty()) {
        fail("malformed header line " + std::to_string(n) + ": '" + excerpt(t) +
             "' (expected 'Key = Value')");
      }
      const std::string key = trim(t.substr(0, eq));
      const std::string value = trim(t.substr(eq + 1));
      h.keys[key] = value;
      if (key == "ElementDataFile") {
        h.data_file = value;
        const long pos = std::ftell(f);
        if (pos < 0) fail("cannot tell position in file: " + std::string(std::strerror(errno)));
        h.data_offset = static_cast<std::uint64_t>(pos);
        return h;
      }
    }
  }

  const std::string* find(const Header& h, const char* key) const {
    const auto it = h.keys.find(key);
    return it == h.keys.end() ? nullptr : &it->second;
  }

  const std::string& require(const Header& h, const char* key) const {
    const std::string* v = find(h, key);
    if (!v) fail(std::string("missing ") + key + " in the header");
    return *v;
  }

  long long integer(const std::string& key, const std::string& text) const {
    errno = 0;
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || errno == ERANGE || *end != '\0')
      fail(key + " = '" + excerpt(text) + "' is not an integer");
    return v;
  }

  bool boolean(const std::string& key, const std::string& text) const {
    const std::string t = lower(text);
    if (t == "true" || t == "1") return true;
    if (t == "false" || t == "0") return false;
    fail(key + " = '" + excerpt(text) + "' is not True or False");
  }

  // Exactly `count` finite reals.
  std::vector<double> reals(const std::string& key, const std::string& text, std::size_t count) const {
    const auto w = words(text);
    if (w.size() != count) {
      fail(key + " = '" + excerpt(text) + "': expected " + std::to_string(count) + " numbers");
    }
    std::vector<double> out;
    for (const std::string& s : w) {
      errno = 0;
      char* end = nullptr;
      const double x = std::strtod(s.c_str(), &end);
      if (errno == ERANGE || *end != '\0' || !std::isfinite(x))
        fail(key + " = '" + excerpt(text) + "': '" + excerpt(s) + "' is not a number");
      out.push_back(x);
    }
    return out;
  }

 private:
  // One line without its terminator; false at EOF before any character.
  bool read_line(std::FILE* f, std::string& line) const {
    line.clear();
    int c;
    while ((c = std::fgetc(f)) != EOF) {
      if (c == '\n') return true;
      // NUL in a "header" means we are reading binary data, not text.
      if (c == '\0') fail("not a MetaImage header (binary data before ElementDataFile)");
      line += static_cast<char>(c);
      if (line.size() > kMaxHeaderLine) fail("header line longer than 64 KiB: not a MetaImage header");
    }
    if (std::ferror(f)) fail("read error: " + std::string(std::strerror(errno)));
    return !line.empty();
  }

  std::string path_;
};

// Inflates `in` (zlib or gzip stream) into `out`, producing at most `cap`
// bytes (extra data is ignored). `out` grows with what the stream really
// produces, never to `cap` on the header's word alone.
void inflate_capped(const std::string& path, const std::vector<unsigned char>& in, std::size_t cap,
                    std::vector<unsigned char>& out) {
  z_stream zs{};
  if (inflateInit2(&zs, 15 + 32) != Z_OK) throw input_error(path, "zlib initialisation failed");
  struct End {
    z_stream* z;
    ~End() { inflateEnd(z); }
  } end{&zs};
  out.clear();
  out.resize(std::min<std::size_t>(cap, std::max<std::size_t>(std::size_t(1) << 20, 4 * in.size())));
  std::size_t in_pos = 0, out_pos = 0;
  // avail_in/avail_out are 32-bit: feed > 4 GiB buffers in pieces.
  while (out_pos < cap) {
    if (zs.avail_in == 0 && in_pos < in.size()) {
      const std::size_t chunk = std::min<std::size_t>(in.size() - in_pos, UINT_MAX);
      zs.next_in = const_cast<Bytef*>(in.data() + in_pos);
      zs.avail_in = static_cast<uInt>(chunk);
      in_pos += chunk;
    }
    if (out_pos == out.size()) out.resize(std::min(cap, 2 * out.size()));
    const std::size_t room = std::min<std::size_t>(out.size() - out_pos, UINT_MAX);
    zs.next_out = out.data() + out_pos;
    zs.avail_out = static_cast<uInt>(room);
    const int rc = inflate(&zs, Z_NO_FLUSH);
    out_pos += room - zs.avail_out;
    if (rc == Z_STREAM_END) break;
    if (rc == Z_NEED_DICT || rc == Z_DATA_ERROR || rc == Z_MEM_ERROR) {
      throw input_error(path, std::string("corrupt compressed data: ") +
                                  (zs.msg ? zs.msg : "zlib error " + std::to_string(rc)));
    }
    if (rc == Z_BUF_ERROR && zs.avail_in == 0 && in_pos == in.size()) break;  // input ran out
  }
  out.resize(out_pos);
}


// Shortest text that reads back as exactly `x`.
std::string exact(double x) {
  char buf[64];
  for (int prec = 6; prec <= 17; ++prec) {
    std::snprintf(buf, sizeof buf, "%.*g", prec, x);
    if (std::strtod(buf, nullptr) == x) break;
  }
  return buf;
}

std::string three(const Vec3d& v) { return exact(v[0]) + " " + exact(v[1]) + " " + exact(v[2]); }

}  // namespace

namespace {

// Deflate's largest expansion (zlib's technical details), plus slack for
// the stream's header: data that claims more cannot be what it says.
constexpr std::uint64_t kMaxInflateRatio = 1032;

// Everything the header says, checked, and where the samples are.
struct MetaImage {
  VolumeHeader header;
  bool msb = false, compressed = false;
  std::optional<std::uint64_t> compressed_size;
  FilePtr header_file, data_holder;
  std::FILE* data = nullptr;    // positioned at the first byte of the samples
  std::string data_name;        // for messages
  std::uint64_t available = 0;  // bytes from there to the end of the file
  std::size_t expected = 0;     // bytes of samples (uncompressed)
};

MetaImage open_metaimage(const std::string& path) {
  Parser p(path);
  MetaImage m;
  m.header_file = open_for_reading(path);
  const Header h = p.read_header(m.header_file.get());
  for (const auto& kv : h.keys)
    if (is_tracked_frame_key(kv.first)) throw tracked_frame_error(path, kv.first);

  if (const std::string* ot = p.find(h, "ObjectType"); ot && *ot != "Image")
    p.fail("ObjectType = " + excerpt(*ot) + " is not supported (expected Image)");

  const long long ndims = p.integer("NDims", p.require(h, "NDims"));
  const std::string& dim_text = p.require(h, "DimSize");
  if (ndims != 3) {
    p.fail("expected a 3-D scalar volume, found " + std::to_string(ndims) + "-D data (DimSize " +
           excerpt(dim_text) + ")");
  }
  Dims3 dims{};
  {
    const auto w = words(dim_text);
    if (w.size() != 3) p.fail("DimSize = '" + excerpt(dim_text) + "': expected 3 positive integers");
    for (std::size_t i = 0; i < 3; ++i) {
      const long long d = p.integer("DimSize", w[i]);
      if (d <= 0) p.fail("DimSize = '" + excerpt(dim_text) + "': expected 3 positive integers");
      dims[i] = static_cast<std::size_t>(d);
    }
  }

  const std::string& et = p.require(h, "ElementType");
  std::optional<ScalarType> type;
  for (const auto& e : kElementTypes) {
    if (et == e.name) type = e.type;
  }
  if (!type) p.fail("unknown ElementType " + excerpt(et));

  if (const std::string* ch = p.find(h, "ElementNumberOfChannels")) {
    const long long channels = p.integer("ElementNumberOfChannels", *ch);
    if (channels != 1) {
      p.fail("ElementNumberOfChannels = " + std::to_string(channels) +
             ": expected a scalar volume (1 channel)");
    }
  }
  if (const std::string* bd = p.find(h, "BinaryData"); bd && !p.boolean("BinaryData", *bd))
    p.fail("BinaryData = False (ASCII MetaImage data) is not supported");

  Vec3d spacing{1.0, 1.0, 1.0};
  const std::string* sp = p.find(h, "ElementSpacing");
  const char* sp_key = "ElementSpacing";
  if (!sp) {
    sp = p.find(h, "ElementSize");  // older writers give only the voxel size
    sp_key = "ElementSize";
  }
  if (sp) {
    const auto s = p.reals(sp_key, *sp, 3);
    // A zero or negative step is a broken header, but the samples are fine.
    for (std::size_t i = 0; i < 3; ++i) spacing[i] = s[i] != 0.0 ? std::fabs(s[i]) : 1.0;
  }
  Vec3d origin{0.0, 0.0, 0.0};
  for (const char* key : {"Offset", "Position", "Origin"}) {
    if (const std::string* o = p.find(h, key)) {
      const auto x = p.reals(key, *o, 3);
      origin = {x[0], x[1], x[2]};
      break;
    }
  }
  check_geometry(path, spacing, origin);
  // TransformMatrix: the unit directions of the three index axes, one after
  // another (ITK's MetaImageIO reads axis i from numbers 3i..3i+2). Rows
  // that are not unit length are normalised; a degenerate matrix (a zero
  // row, dependent rows) says nothing usable and leaves the identity.
  WorldFrame frame;
  for (const char* key : {"TransformMatrix", "Rotation", "Orientation"}) {
    const std::string* tm = p.find(h, key);
    if (!tm) continue;
    const auto x = p.reals(key, *tm, 9);
    Mat3 axes{};
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) {
      const double len = std::sqrt(x[3 * a] * x[3 * a] + x[3 * a + 1] * x[3 * a + 1] + x[3 * a + 2] * x[3 * a + 2]);
      ok = std::isfinite(len) && len > 0.0;
      // Unit rows (ITK writes direction cosines) are kept bit for bit.
      const double scale = std::fabs(len - 1.0) <= 1e-12 ? 1.0 : len;
      for (int c = 0; c < 3 && ok; ++c) axes[a][c] = x[3 * a + c] / scale;
    }
    if (ok && std::fabs(determinant(axes)) > 1e-6) frame.axes = axes;
    break;
  }
  if (const std::string* ao = p.find(h, "AnatomicalOrientation")) {
    // Kept to be written back when it is a three-letter code ("RAI").
    const std::string code = upper_ascii(*ao);
    if (code.size() == 3 && code.find_first_not_of("RLAPSI") == std::string::npos) frame.anatomical_orientation = code;
  }

  for (const char* key : {"BinaryDataByteOrderMSB", "ElementByteOrderMSB"}) {
    if (const std::string* b = p.find(h, key)) {
      m.msb = p.boolean(key, *b);
      break;
    }
  }
  if (const std::string* c = p.find(h, "CompressedData")) m.compressed = p.boolean("CompressedData", *c);
  if (const std::string* cs = p.find(h, "CompressedDataSize"); cs && m.compressed) {
    const long long n = p.integer("CompressedDataSize", *cs);
    if (n < 0) p.fail("CompressedDataSize = " + std::to_string(n) + " is negative");
    m.compressed_size = static_cast<std::uint64_t>(n);
  }
  long long header_size = 0;
  if (const std::string* hs = p.find(h, "HeaderSize")) {
    header_size = p.integer("HeaderSize", *hs);
    if (header_size < -1) p.fail("HeaderSize = " + std::to_string(header_size) + " is invalid");
  }

  const std::string& df = h.data_file;
  if (df.empty()) p.fail("ElementDataFile is empty");
  if (df == "LIST" || df.rfind("LIST ", 0) == 0 || df.find('%') != std::string::npos)
    p.fail("ElementDataFile LIST/pattern not supported ('" + excerpt(df) + "')");

  const std::size_t voxels = checked_voxels(path, dims, *type);
  m.expected = voxels * scalar_type_size(*type);  // checked_voxels ruled out overflow
  m.header.dims = dims;
  m.header.type = *type;
  m.header.spacing = spacing;
  m.header.origin = origin;
  m.header.frame = frame;
  m.header.files = {path};

  // Where the samples live: after the header (LOCAL) or in another file.
  m.data = m.header_file.get();
  m.data_name = path;
  std::uint64_t begin = h.data_offset;
  std::uint64_t total = file_size(m.data);
  if (df != "LOCAL") {
    m.data_name = resolve_data_file(path, df);
    m.header.files.push_back(m.data_name);
    m.data_holder = open_for_reading(m.data_name);
    m.data = m.data_holder.get();
    total = file_size(m.data);
    if (header_size == -1) {
      // Data at the end of the file: skip whatever precedes it.
      if (m.compressed) p.fail("HeaderSize = -1 cannot be used with CompressedData");
      if (total < m.expected) {
        p.fail("data file " + df + " has " + std::to_string(total) + " bytes, expected at least " +
               std::to_string(m.expected));
      }
      begin = total - m.expected;
    } else {
      begin = static_cast<std::uint64_t>(header_size);
      if (!m.compressed && header_size == 0 && total != m.expected) {
        p.fail("data file " + df + " has " + std::to_string(total) + " bytes, expected " +
               std::to_string(m.expected));
      }
    }
  }
  if (std::fseek(m.data, static_cast<long>(std::min<std::uint64_t>(begin, LONG_MAX)), SEEK_SET) != 0)
    p.fail("cannot seek in data file " + df + ": " + std::strerror(errno));
  m.available = total > begin ? total - begin : 0;

  // Sizes against the file, before anything of the declared size exists.
  if (!m.compressed && m.available < m.expected) {
    p.fail("data truncated: expected " + std::to_string(m.expected) + " bytes, found " + std::to_string(m.available));
  }
  if (m.compressed) {
    std::uint64_t packed = m.available;
    if (m.compressed_size) {
      if (*m.compressed_size > m.available) {
        p.fail("compressed data truncated: CompressedDataSize = " + std::to_string(*m.compressed_size) +
               " bytes, found " + std::to_string(m.available));
      }
      packed = *m.compressed_size;
    }
    if (m.expected > kMaxInflateRatio * packed + 1024) {
      p.fail("data truncated: " + std::to_string(packed) + " bytes of compressed data cannot hold the " +
             std::to_string(m.expected) + " bytes declared (zlib expands at most 1032-fold)");
    }
  }
  return m;
}

}  // namespace

VolumeHeader read_metaimage_header(const std::string& path) { return open_metaimage(path).header; }

Volume read_metaimage(const std::string& path) {
  MetaImage m = open_metaimage(path);
  const Parser p(path);
  std::vector<unsigned char> bytes;
  if (!m.compressed) {
    bytes.resize(m.expected);
    const std::size_t got = read_up_to(m.data, bytes.data(), m.expected, m.data_name);
    if (got < m.expected) {
      p.fail("data truncated: expected " + std::to_string(m.expected) + " bytes, found " + std::to_string(got));
    }
  } else {
    const std::uint64_t want = m.compressed_size.value_or(m.available);
    if (want > SIZE_MAX || !fits_in_memory(static_cast<std::size_t>(want), 1))
      p.fail("compressed data of " + std::to_string(want) + " bytes does not fit in memory");
    std::vector<unsigned char> packed(static_cast<std::size_t>(want));
    const std::size_t got = read_up_to(m.data, packed.data(), packed.size(), m.data_name);
    packed.resize(got);
    inflate_capped(path, packed, m.expected, bytes);
    if (bytes.size() < m.expected) {
      p.fail("data truncated: expected " + std::to_string(m.expected) + " bytes after decompression, found " +
             std::to_string(bytes.size()));
    }
  }

  Volume v(m.header.dims, m.header.spacing, m.header.type);
  v.origin = m.header.origin;
  v.frame = m.header.frame;
  decode_samples(bytes.data(), v.voxels(), m.header.type, m.msb != host_is_big_endian(), v.data.data());
  return v;
}

std::vector<unsigned char> deflate_all(const std::string& path, const std::vector<unsigned char>& in, bool gzip) {
  z_stream zs{};
  if (deflateInit2(&zs, Z_DEFAULT_COMPRESSION, Z_DEFLATED, gzip ? 15 + 16 : 15, 8, Z_DEFAULT_STRATEGY) != Z_OK)
    throw input_error(path, "zlib initialisation failed");
  struct End {
    z_stream* z;
    ~End() { deflateEnd(z); }
  } end{&zs};
  std::vector<unsigned char> out;
  std::vector<unsigned char> buf(1 << 20);
  std::size_t in_pos = 0;
  int rc = Z_OK;
  do {
    if (zs.avail_in == 0 && in_pos < in.size()) {
      const std::size_t chunk = std::min<std::size_t>(in.size() - in_pos, UINT_MAX);
      zs.next_in = const_cast<Bytef*>(in.data() + in_pos);
      zs.avail_in = static_cast<uInt>(chunk);
      in_pos += chunk;
    }
    const int flush = (in_pos == in.size() && zs.avail_in == 0) ? Z_FINISH : Z_NO_FLUSH;
    zs.next_out = buf.data();
    zs.avail_out = static_cast<uInt>(buf.size());
    rc = deflate(&zs, flush);
    if (rc == Z_STREAM_ERROR) throw input_error(path, "cannot write: zlib compression failed");
    out.insert(out.end(), buf.data(), buf.data() + (buf.size() - zs.avail_out));
  } while (rc != Z_STREAM_END);
  return out;
}

void write_metaimage(const std::string& path, const Volume& v, const WriteOptions& opt,
                     bool detached) {
  const ScalarType type = opt.type.value_or(v.source_type);
  const std::size_t elem = scalar_type_size(type);
  // MetaImage files here are always little-endian (MSB = False).
  const auto encode = [&](std::size_t begin, std::size_t count) {
    const std::vector<float> part(v.data.begin() + long(begin), v.data.begin() + long(begin + count));
    std::vector<unsigned char> bytes = encode_samples(part, type);
    if (host_is_big_endian())
      for (std::size_t i = 0; i + elem <= bytes.size(); i += elem) std::reverse(&bytes[i], &bytes[i] + elem);
    return bytes;
  };
  // Compressed data is needed whole (its size goes in the header); plain
  // data is encoded and written a chunk at a time, no copy of the volume.
  std::vector<unsigned char> packed;
  if (opt.compress) packed = deflate_all(path, encode(0, v.data.size()));
  const auto write_samples = [&](AtomicFile& out) {
    if (opt.compress) return out.write(packed.data(), packed.size());
    constexpr std::size_t kChunk = std::size_t(1) << 20;
    for (std::size_t i = 0; i < v.data.size(); i += kChunk) {
      const auto bytes = encode(i, std::min(kChunk, v.data.size() - i));
      out.write(bytes.data(), bytes.size());
    }
  };

  std::string data_file = "LOCAL";
  if (detached) data_file = fs::path(path).stem().string() + (opt.compress ? ".zraw" : ".raw");

  std::ostringstream hdr;
  hdr << "ObjectType = Image\n"
      << "NDims = 3\n"
      << "BinaryData = True\n"
      << "BinaryDataByteOrderMSB = False\n"
      << "CompressedData = " << (opt.compress ? "True" : "False") << "\n";
  if (opt.compress) hdr << "CompressedDataSize = " << packed.size() << "\n";
  // MetaImage's world is ITK's LPS: a RAS or LAS volume is converted (the
  // same physical placement); other spaces are written as they are.
  Vec3d origin = v.origin;
  const WorldFrame frame = v.frame.to_lps(origin);
  hdr << "TransformMatrix = " << three(frame.axes[0]) << " " << three(frame.axes[1]) << " " << three(frame.axes[2])
      << "\n"
      << "Offset = " << three(origin) << "\n";
  if (frame.anatomical()) {
    hdr << "AnatomicalOrientation = "
        << (frame.anatomical_orientation.empty() ? lps_orientation_code(frame.axes) : frame.anatomical_orientation)
        << "\n";
  }
  hdr << "ElementSpacing = " << three(v.spacing) << "\n"
      << "DimSize = " << v.dims[0] << " " << v.dims[1] << " " << v.dims[2] << "\n"
      << "ElementType = " << element_type_name(type) << "\n"
      << "ElementDataFile = " << data_file << "\n";
  const std::string header = hdr.str();

  if (!detached) {
    AtomicFile out(path);
    out.write(header.data(), header.size());
    write_samples(out);
    out.commit();
    return;
  }
  // Both complete before either replaces its target, and published under
  // one directory lock (data first: a header never points at a data file
  // that is not there yet), so concurrent writers never mix them.
  AtomicFile data_out((fs::path(path).parent_path() / data_file).string());
  AtomicFile header_out(path);
  write_samples(data_out);
  header_out.write(header.data(), header.size());
  AtomicFile::commit_together({&data_out, &header_out});
}

}  // namespace softshell::io_detail
