// MetaImage (.mha / .mhd) reading and writing, hand-written: the format is a
// "Key = Value" text header ending with ElementDataFile, followed by (LOCAL)
// or pointing to (detached) the samples, optionally zlib-compressed. Only
// 3-D single-channel images are accepted; see docs/formats.md.
#include <zlib.h>

#include <algorithm>
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

// Inflates all of `in` (zlib or gzip stream) into `out`, which has exactly
// the expected size. Returns the number of bytes produced.
std::size_t inflate_into(const std::string& path, const std::vector<unsigned char>& in,
                         std::vector<unsigned char>& out) {
  z_stream zs{};
  if (inflateInit2(&zs, 15 + 32) != Z_OK) throw input_error(path, "zlib initialisation failed");
  struct End {
    z_stream* z;
    ~End() { inflateEnd(z); }
  } end{&zs};
  std::size_t in_pos = 0, out_pos = 0;
  int rc = Z_OK;
  // avail_in/avail_out are 32-bit: feed > 4 GiB buffers in pieces.
  while (true) {
    if (zs.avail_in == 0 && in_pos < in.size()) {
      const std::size_t chunk = std::min<std::size_t>(in.size() - in_pos, UINT_MAX);
      zs.next_in = const_cast<Bytef*>(in.data() + in_pos);
      zs.avail_in = static_cast<uInt>(chunk);
      in_pos += chunk;
    }
    if (zs.avail_out == 0 && out_pos < out.size()) {
      const std::size_t chunk = std::min<std::size_t>(out.size() - out_pos, UINT_MAX);
      zs.next_out = out.data() + out_pos;
      zs.avail_out = static_cast<uInt>(chunk);
      out_pos += chunk;
    }
    if (zs.avail_out == 0) break;  // got everything we need; extra data is ignored
    rc = inflate(&zs, Z_NO_FLUSH);
    if (rc == Z_STREAM_END) break;
    if (rc == Z_NEED_DICT || rc == Z_DATA_ERROR || rc == Z_MEM_ERROR) {
      throw input_error(path, std::string("corrupt compressed data: ") +
                                  (zs.msg ? zs.msg : "zlib error " + std::to_string(rc)));
    }
    if (rc == Z_BUF_ERROR && zs.avail_in == 0 && in_pos == in.size()) break;  // input ran out
  }
  return out_pos - zs.avail_out;
}

// Deflates `in` to a zlib stream, as MetaIO (ITK, VTK, PLUS) writes it.
std::vector<unsigned char> deflate_all(const std::string& path, const std::vector<unsigned char>& in) {
  z_stream zs{};
  if (deflateInit(&zs, Z_DEFAULT_COMPRESSION) != Z_OK) throw input_error(path, "zlib initialisation failed");
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

Volume read_metaimage(const std::string& path) {
  Parser p(path);
  FilePtr f = open_for_reading(path);
  const Header h = p.read_header(f.get());

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
  // TransformMatrix (orientation) is accepted but not applied: softshell
  // works on the voxel grid; only spacing and origin matter.
  if (const std::string* tm = p.find(h, "TransformMatrix")) p.reals("TransformMatrix", *tm, 9);

  bool msb = false;
  for (const char* key : {"BinaryDataByteOrderMSB", "ElementByteOrderMSB"}) {
    if (const std::string* b = p.find(h, key)) {
      msb = p.boolean(key, *b);
      break;
    }
  }
  bool compressed = false;
  if (const std::string* c = p.find(h, "CompressedData")) compressed = p.boolean("CompressedData", *c);
  std::optional<std::uint64_t> compressed_size;
  if (const std::string* cs = p.find(h, "CompressedDataSize"); cs && compressed) {
    const long long n = p.integer("CompressedDataSize", *cs);
    if (n < 0) p.fail("CompressedDataSize = " + std::to_string(n) + " is negative");
    compressed_size = static_cast<std::uint64_t>(n);
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
  const std::size_t elem = scalar_type_size(*type);
  const std::size_t expected = voxels * elem;  // checked_voxels ruled out overflow

  // Where the samples live: after the header (LOCAL) or in another file.
  FilePtr data_holder;
  std::FILE* data = f.get();
  std::string data_name = path;  // for messages
  std::uint64_t begin = h.data_offset;
  std::uint64_t total = file_size(f.get());
  const bool local = df == "LOCAL";
  if (!local) {
    const fs::path rel(df);
    const fs::path full = rel.is_absolute() ? rel : fs::path(path).parent_path() / rel;
    data_name = full.string();
    try {
      data_holder = open_for_reading(data_name);
    } catch (const InputError& e) {
      p.fail(std::string("data file ") + e.what());  // "<data file>: cannot open: <why>"
    }
    data = data_holder.get();
    total = file_size(data);
    if (header_size == -1) {
      // Data at the end of the file: skip whatever precedes it.
      if (compressed) p.fail("HeaderSize = -1 cannot be used with CompressedData");
      if (total < expected) {
        p.fail("data file " + df + " has " + std::to_string(total) + " bytes, expected at least " +
               std::to_string(expected));
      }
      begin = total - expected;
    } else {
      begin = static_cast<std::uint64_t>(header_size);
      if (!compressed && header_size == 0 && total != expected) {
        p.fail("data file " + df + " has " + std::to_string(total) + " bytes, expected " +
               std::to_string(expected));
      }
    }
    if (std::fseek(data, static_cast<long>(std::min<std::uint64_t>(begin, LONG_MAX)), SEEK_SET) != 0)
      p.fail("cannot seek in data file " + df + ": " + std::strerror(errno));
  }
  const std::uint64_t available = total > begin ? total - begin : 0;

  if (!compressed && available < expected) {
    // Fail before allocating what a lying header asks for.
    p.fail("data truncated: expected " + std::to_string(expected) + " bytes, found " + std::to_string(available));
  }
  std::vector<unsigned char> bytes(expected);
  if (!compressed) {
    const std::size_t got = read_up_to(data, bytes.data(), expected, data_name);
    if (got < expected) {
      p.fail("data truncated: expected " + std::to_string(expected) + " bytes, found " + std::to_string(got));
    }
  } else {
    std::uint64_t want = available;
    if (compressed_size) {
      if (*compressed_size > available) {
        p.fail("compressed data truncated: CompressedDataSize = " + std::to_string(*compressed_size) +
               " bytes, found " + std::to_string(available));
      }
      want = *compressed_size;
    }
    if (want > SIZE_MAX || !fits_in_memory(static_cast<std::size_t>(want), 1))
      p.fail("compressed data of " + std::to_string(want) + " bytes does not fit in memory");
    std::vector<unsigned char> packed(static_cast<std::size_t>(want));
    const std::size_t got = read_up_to(data, packed.data(), packed.size(), data_name);
    packed.resize(got);
    const std::size_t produced = inflate_into(path, packed, bytes);
    if (produced < expected) {
      p.fail("data truncated: expected " + std::to_string(expected) +
             " bytes after decompression, found " + std::to_string(produced));
    }
  }

  Volume v(dims, spacing, *type);
  v.origin = origin;
  decode_samples(bytes.data(), voxels, *type, msb != host_is_big_endian(), v.data.data());
  return v;
}

void write_metaimage(const std::string& path, const Volume& v, const WriteOptions& opt,
                     bool detached) {
  const ScalarType type = opt.type.value_or(v.source_type);
  std::vector<unsigned char> bytes = encode_samples(v.data, type);
  if (host_is_big_endian()) {
    // MetaImage files here are always little-endian (MSB = False).
    const std::size_t e = scalar_type_size(type);
    for (std::size_t i = 0; i + e <= bytes.size(); i += e) std::reverse(&bytes[i], &bytes[i] + e);
  }
  if (opt.compress) bytes = deflate_all(path, bytes);

  std::string data_file = "LOCAL";
  if (detached) data_file = fs::path(path).stem().string() + (opt.compress ? ".zraw" : ".raw");

  std::ostringstream hdr;
  hdr << "ObjectType = Image\n"
      << "NDims = 3\n"
      << "BinaryData = True\n"
      << "BinaryDataByteOrderMSB = False\n"
      << "CompressedData = " << (opt.compress ? "True" : "False") << "\n";
  if (opt.compress) hdr << "CompressedDataSize = " << bytes.size() << "\n";
  hdr << "TransformMatrix = 1 0 0 0 1 0 0 0 1\n"
      << "Offset = " << three(v.origin) << "\n"
      << "ElementSpacing = " << three(v.spacing) << "\n"
      << "DimSize = " << v.dims[0] << " " << v.dims[1] << " " << v.dims[2] << "\n"
      << "ElementType = " << element_type_name(type) << "\n"
      << "ElementDataFile = " << data_file << "\n";
  const std::string header = hdr.str();

  if (!detached) {
    AtomicFile out(path);
    out.write(header.data(), header.size());
    out.write(bytes.data(), bytes.size());
    out.commit();
    return;
  }
  // Data first: a header never points at a data file that is not there yet.
  AtomicFile data_out((fs::path(path).parent_path() / data_file).string());
  AtomicFile header_out(path);
  data_out.write(bytes.data(), bytes.size());
  header_out.write(header.data(), header.size());
  data_out.commit();
  header_out.commit();
}

}  // namespace softshell::io_detail
