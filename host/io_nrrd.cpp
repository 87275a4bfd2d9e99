// NRRD reading and writing through Teem, the format's reference
// implementation: every encoding Teem knows (raw, gzip, bzip2, ascii, hex)
// and detached headers (.nhdr) come for free. Teem reports errors through
// biff; they are turned into one-line InputErrors here.
//
// Teem trusts its input more than softshell can: it opens a header's data
// file (standard input for "-", a FIFO that blocks, any absolute path),
// formats data file names with a printf pattern from the header, and
// allocates what the header declares before reading a byte. So the header is
// scanned here first (scan_header) and every data file and size checked
// before Teem sees the file; see docs/formats.md.
#include <bzlib.h>
#include <teem/nrrd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <limits>
#include <mutex>
#include <optional>
#include <sstream>

#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::io_detail {

namespace {

// biff and nrrdStateVerboseIO are process-global; serialise Teem calls.
std::mutex& teem_mutex() {
  static std::mutex m;
  return m;
}

struct NrrdNuker {
  void operator()(Nrrd* n) const { nrrdNuke(n); }  // frees the data too
};
struct NrrdNixer {
  void operator()(Nrrd* n) const { nrrdNix(n); }  // leaves wrapped data alone
};
struct IoStateNixer {
  void operator()(NrrdIoState* s) const { nrrdIoStateNix(s); }
};
struct CFree {
  void operator()(char* p) const { std::free(p); }
};
using NrrdOwned = std::unique_ptr<Nrrd, NrrdNuker>;
using NrrdWrapper = std::unique_ptr<Nrrd, NrrdNixer>;
using IoStatePtr = std::unique_ptr<NrrdIoState, IoStateNixer>;

// Teem's biff message, outermost call first, one "[nrrd] func: text" line
// per level. The innermost (last) line with text is the most specific.
std::string take_biff_message() {
  const std::unique_ptr<char, CFree> raw(biffGetDone(NRRD));
  if (!raw) return "unknown Teem error";
  std::istringstream in(raw.get());
  std::string line, best, best_func, sizes;
  while (std::getline(in, line)) {
    const auto bar = line.find("sizes info |");
    if (bar != std::string::npos) {
      sizes = line.substr(bar + 12);
      if (!sizes.empty() && sizes.back() == '|') sizes.pop_back();
    }
    std::string func;
    if (line.rfind("[", 0) == 0) {
      const auto close = line.find("] ");
      if (close != std::string::npos) line.erase(0, close + 2);
      const auto colon = line.find(": ");
      if (colon != std::string::npos && line.find(' ') > colon) {
        func = line.substr(0, colon);
        line.erase(0, colon + 2);
      } else if (!line.empty() && line.back() == ':' && line.find(' ') == std::string::npos) {
        line.clear();  // "func:" with nothing after it
      }
    }
    for (char& c : line) {
      if (static_cast<unsigned char>(c) < 0x20) c = ' ';
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    if (!line.empty()) {
      best = line;
      best_func = func;
    }
  }
  if (best.empty()) return "unknown Teem error";
  // Say it the way the other readers do, with the offending sizes.
  if (best_func == "_nrrdSizeCheck" && !sizes.empty())
    return "sizes " + sizes + " overflow the voxel count (too large for this machine)";
  // Errors from the data decoders read better with context.
  const bool decoder = best_func.rfind("_nrrdEncoding", 0) == 0 &&
                       best_func.size() > 5 && best_func.compare(best_func.size() - 5, 5, "_read") == 0;
  if (decoder) best = "data truncated or corrupt: " + best;
  return best;
}

std::optional<ScalarType> scalar_type_of(int nrrd_type) {
  switch (nrrd_type) {
    case nrrdTypeChar: return ScalarType::Int8;
    case nrrdTypeUChar: return ScalarType::UInt8;
    case nrrdTypeShort: return ScalarType::Int16;
    case nrrdTypeUShort: return ScalarType::UInt16;
    case nrrdTypeInt: return ScalarType::Int32;
    case nrrdTypeUInt: return ScalarType::UInt32;
    case nrrdTypeLLong: return ScalarType::Int64;
    case nrrdTypeULLong: return ScalarType::UInt64;
    case nrrdTypeFloat: return ScalarType::Float32;
    case nrrdTypeDouble: return ScalarType::Float64;
    default: return std::nullopt;
  }
}

int nrrd_type_of(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return nrrdTypeChar;
    case ScalarType::UInt8: return nrrdTypeUChar;
    case ScalarType::Int16: return nrrdTypeShort;
    case ScalarType::UInt16: return nrrdTypeUShort;
    case ScalarType::Int32: return nrrdTypeInt;
    case ScalarType::UInt32: return nrrdTypeUInt;
    case ScalarType::Int64: return nrrdTypeLLong;
    case ScalarType::UInt64: return nrrdTypeULLong;
    case ScalarType::Float32: return nrrdTypeFloat;
    case ScalarType::Float64: return nrrdTypeDouble;
  }
  return nrrdTypeUnknown;
}

std::string sizes_text(const Nrrd* n) {
  std::string s;
  for (unsigned i = 0; i < n->dim; ++i) s += (i ? " " : "") + std::to_string(n->axis[i].size);
  return s;
}

// ---- the header, scanned before Teem reads it -------------------------------------

constexpr std::size_t kMaxHeaderLine = 64 * 1024;
// Longest field line (content excepted) handed to Teem: its error messages
// quote a field into a 1 KiB buffer.
constexpr std::size_t kMaxFieldLine = 800;
constexpr int kMaxHeaderLines = 100000;

struct HeaderScan {
  std::uint64_t data_offset = 0;  // first byte after the header (attached data)
  std::string data_file;          // resolved detached data file; empty: attached
};

// Reads the header up to its blank line, checks the magic and applies the
// data-file policy to every "data file" field.
HeaderScan scan_header(const std::string& path) {
  FilePtr f = open_for_reading(path);
  HeaderScan scan;
  std::string line;
  // Lines end as Teem's reader ends them (airOneLine): at "\n", "\r\n" or a
  // lone "\r" (a "\r" inside a field ended it early for Teem, and an
  // unterminated "space units" quote leaked: found by garbling headers).
  auto next_line = [&]() -> bool {
    line.clear();
    int c;
    while ((c = std::fgetc(f.get())) != EOF && c != '\n' && c != '\r') {
      line += static_cast<char>(c);
      if (line.size() > kMaxHeaderLine) throw input_error(path, "header line longer than 64 KiB: not a NRRD header");
    }
    if (c == '\r') {
      const int d = std::fgetc(f.get());
      if (d != '\n' && d != EOF) std::ungetc(d, f.get());
    }
    if (std::ferror(f.get())) throw input_error(path, "read error: " + std::string(std::strerror(errno)));
    return c != EOF || !line.empty();
  };
  // Without the magic Teem would try its other formats (plain text tables,
  // PNM, VTK), none of which is a volume softshell means to read.
  // Exactly the magics Teem 1.12 knows: anything else it would hand on.
  if (!next_line() || line.size() != 8 || line.rfind("NRRD000", 0) != 0 || line[7] < '1' || line[7] > '6')
    throw input_error(path, "not a NRRD file (the first line is not NRRD0001 to NRRD0006)");
  // Teem's own checks of field order leak what it parsed so far (seen
  // under AddressSanitizer by fuzzing): a per-axis field before
  // "dimension", and "block size" with a type that is not "block". Those
  // are refused here with the message Teem would give.
  bool have_dimension = false, block_size = false;
  std::string type;
  int space_dim = 0;  // from "space" or "space dimension" (0: none yet)
  int dimension = 0;  // from "dimension"
  // Complete quoted strings in a field's value ("\"" inside one is a quote,
  // as Teem reads it); -1 when a quote is not closed or text lies between.
  const auto quoted_count = [](const std::string& value) {
    int count = 0;
    std::size_t i = 0;
    for (;;) {
      while (i < value.size() && (value[i] == ' ' || value[i] == '\t')) ++i;
      if (i == value.size()) return count;
      if (value[i] != '"') return -1;
      std::size_t close = i + 1;
      while (close < value.size() && !(value[close] == '"' && value[close - 1] != '\\')) ++close;
      if (close >= value.size()) return -1;
      ++count, i = close + 1;
    }
  };
  for (int n = 2; next_line(); ++n) {
    if (n > kMaxHeaderLines) throw input_error(path, "header longer than 100000 lines");
    if (line.empty()) break;  // end of the header
    // A header is text: Teem reads a line only up to a NUL, so a field
    // name followed by a NUL is a field to Teem but not to the scan below
    // (a per-axis field before "dimension" reached Teem's leaking error
    // path that way: found by fuzzing).
    if (line.find('\0') != std::string::npos)
      throw input_error(path, "header line " + std::to_string(n) + " contains a NUL byte: not a NRRD header");
    if (line[0] == '#') continue;  // a comment
    const auto colon = line.find(':');
    // Teem formats a line it cannot parse into a fixed 1 KiB error buffer
    // with vsprintf: a long unparsable line overflowed it ("buffer overflow
    // detected", found by fuzzing). Such lines are refused here, and field
    // lines Teem could quote in an error are kept short.
    const auto unparsable = [&] {
      return input_error(path, "header line " + std::to_string(n) +
                                   " is neither a NRRD field (\"name: value\"), a key/value pair (\"key:=value\") nor a "
                                   "comment");
    };
    if (colon == std::string::npos) throw unparsable();
    // A key/value pair has ":=" at its first colon; a field may hold ":="
    // further on (Teem parses it as the field: found by fuzzing).
    if (colon + 1 < line.size() && line[colon + 1] == '=') {
      // A key/value pair: a PLUS tracked-frame sequence's keys refuse the file.
      const std::string kv_key = trim(line.substr(0, colon));
      if (is_tracked_frame_key(kv_key)) throw tracked_frame_error(path, kv_key);
      continue;
    }
    // A field is "<name>: <value>" (colon and space): Teem does not take
    // "dimension:<garbage>" as the dimension, so per-axis fields after it
    // still come before a dimension for Teem (found by fuzzing).
    if (colon + 1 >= line.size() || line[colon + 1] != ' ') throw unparsable();
    std::string key;
    for (char c : line.substr(0, colon))
      if (c != ' ' && c != '\t') key += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    // Teem's fields (nrrdField, spaces ignored); content is free text Teem never quotes back.
    static const char* const kFields[] = {
        "content", "number", "type", "blocksize", "dimension", "space", "spacedimension", "sizes", "spacings",
        "thicknesses", "axismins", "axismaxs", "spacedirections", "centers", "centerings", "kinds", "labels", "units",
        "min", "max", "oldmin", "oldmax", "endian", "encoding", "lineskip", "byteskip", "sampleunits", "spaceunits",
        "spaceorigin", "measurementframe", "datafile"};
    if (std::find(std::begin(kFields), std::end(kFields), key) == std::end(kFields)) throw unparsable();
    if (key != "content" && line.size() > kMaxFieldLine)
      throw input_error(path, "header line " + std::to_string(n) + " (field '" + trim(line.substr(0, colon)) +
                                  "') is longer than " + std::to_string(kMaxFieldLine) + " characters");
    static const char* const kPerAxis[] = {"sizes", "spacings", "thicknesses", "axismins", "axismaxs", "centers",
                                           "centerings", "labels", "units", "kinds", "spacedirections"};
    if (key == "dimension") have_dimension = true, dimension = std::atoi(trim(line.substr(colon + 1)).c_str());
    if (key == "blocksize") block_size = true;
    if (key == "type") type = trim(line.substr(colon + 1));
    if (!have_dimension && std::find(std::begin(kPerAxis), std::end(kPerAxis), key) != std::end(kPerAxis))
      throw input_error(path, "field '" + trim(line.substr(0, colon)) + "' comes before 'dimension'");
    if (key == "space") {
      const std::string name = lower(trim(line.substr(colon + 1)));
      space_dim = name.size() > 5 && name.compare(name.size() - 5, 5, "-time") == 0 ? 4 : 3;
    }
    if (key == "spacedimension") space_dim = std::atoi(trim(line.substr(colon + 1)).c_str());
    // "space units": Teem leaks on an unterminated quote and on more units
    // than the space has (found by garbling softshell's own headers); one
    // complete quoted unit per world axis, checked here.
    if (key == "spaceunits" && space_dim > 0) {
      const int units = quoted_count(line.substr(colon + 1));
      if (units < 0 || units > space_dim)
        throw input_error(path, "space units: expected one quoted unit per world axis (" + std::to_string(space_dim) +
                                    "), e.g. \"mm\" \"mm\" \"mm\"");
    }
    // "units" and "labels", one quoted string per axis: Teem leaks on an
    // unterminated quote there too (found by fuzz_nrrd in CI's smoke run,
    // 2026-11-26), and on a count other than the dimension.
    if ((key == "units" || key == "labels") && dimension > 0) {
      const int strings = quoted_count(line.substr(colon + 1));
      if (strings != dimension)
        throw input_error(path, key + ": expected one quoted string per axis (" + std::to_string(dimension) +
                                    "), e.g. \"mm\" \"mm\" \"mm\"");
    }
    if (key != "datafile") continue;
    std::string value = line.substr(colon + 1);
    value.erase(0, value.find_first_not_of(" \t"));
    // Teem formats a name containing %d with the header's own pattern (a
    // printf format from the file) and reads further header lines after
    // LIST; softshell reads one data file per volume.
    if (value.rfind("LIST", 0) == 0 || value.find('%') != std::string::npos)
      throw input_error(path, "data file '" + value.substr(0, 40) +
                                  "': lists and numbered patterns of data files are not supported (one data file per volume)");
    scan.data_file = resolve_data_file(path, value);
  }
  if (block_size && type != "block")
    throw input_error(path, "'block size' given for type '" + type.substr(0, 40) + "' (only type block has one)");
  const long pos = std::ftell(f.get());
  scan.data_offset = pos > 0 ? static_cast<std::uint64_t>(pos) : 0;
  return scan;
}

// ---- Teem ------------------------------------------------------------------------

struct LoadInfo {
  const NrrdEncoding* encoding = nullptr;
  long byte_skip = 0;
  unsigned line_skip = 0;
};

// Loads `path` into `n`; header only when `header_only`.
LoadInfo load(Nrrd* n, const std::string& path, bool header_only) {
  IoStatePtr nio(nrrdIoStateNew());
  if (!nio) throw input_error(path, "out of memory");
  if (header_only) nrrdIoStateSet(nio.get(), nrrdIoStateSkipData, AIR_TRUE);
  if (nrrdLoad(n, path.c_str(), nio.get()) != 0) throw input_error(path, take_biff_message());
  return {nio->encoding, nio->byteSkip, nio->lineSkip};
}

// Positive spacing of axis `ax` from "spacings" or "space directions"; 1 mm
// when the file gives none.
double axis_spacing(const Nrrd* n, unsigned ax) {
  double sp = AIR_NAN;
  double dir[NRRD_SPACE_DIM_MAX];
  nrrdSpacingCalculate(n, ax, &sp, dir);
  sp = std::fabs(sp);  // a flipped axis still has a positive step
  return std::isfinite(sp) && sp > 0.0 ? sp : 1.0;
}

// Millimetres in one of NRRD's "space units" (free text; the common names
// of the lengths scanners and toolkits write); nullopt when unknown.
std::optional<double> millimetres_per_unit(std::string u) {
  u = lower(trim(u));
  if (u == "mm" || u == "millimeter" || u == "millimeters" || u == "millimetre" || u == "millimetres") return 1.0;
  if (u == "cm" || u == "centimeter" || u == "centimeters" || u == "centimetre" || u == "centimetres") return 10.0;
  if (u == "m" || u == "meter" || u == "meters" || u == "metre" || u == "metres") return 1000.0;
  if (u == "um" || u == "\xc2\xb5m" || u == "micron" || u == "microns" || u == "micrometer" || u == "micrometers" ||
      u == "micrometre" || u == "micrometres")
    return 1e-3;
  return std::nullopt;
}

// The orientation of a loaded header: unit axes from a 3-D space's "space
// directions" (identity when there is no 3-D space, when an axis has no
// direction or when they are degenerate), the space's name, the
// measurement frame.
WorldFrame frame_of(const Nrrd* n) {
  WorldFrame f;
  if (n->spaceDim != 3) return f;  // no space, or one with time: grid-aligned, unnamed
  if (n->space != nrrdSpaceUnknown) f.space = airEnumStr(nrrdSpace, n->space);
  Mat3 axes{};
  bool ok = true;
  for (unsigned ax = 0; ax < 3 && ok; ++ax) {
    const double* d = n->axis[ax].spaceDirection;
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    ok = std::isfinite(len) && len > 0.0;
    for (unsigned c = 0; c < 3 && ok; ++c) axes[ax][c] = d[c] / len;
  }
  if (ok && std::fabs(determinant(axes)) > 1e-6) {
    f.axes = axes;
    WorldFrame::Exact e;
    e.axes = axes;
    for (unsigned ax = 0; ax < 3; ++ax)
      for (unsigned c = 0; c < 3; ++c) e.directions[ax][c] = n->axis[ax].spaceDirection[c];
    f.as_read = e;
  }
  if (AIR_EXISTS(n->measurementFrame[0][0])) {
    Mat3 mf{};
    bool finite = true;
    for (unsigned i = 0; i < 3; ++i)
      for (unsigned j = 0; j < 3; ++j) {
        mf[i][j] = n->measurementFrame[i][j];
        finite = finite && std::isfinite(mf[i][j]);
      }
    if (finite) f.measurement_frame = mf;
  }
  return f;
}

// Dims, type, spacing and origin of a loaded header, validated. A 4-D
// header whose slowest axis holds frames (kind list, time, domain or none:
// 3D Slicer's Sequences module and PLUS's .igs.nrrd write 3D+t so) is a
// sequence: dims are one frame's, `frames` the count.
VolumeHeader geometry(const Nrrd* n, const std::string& path) {
  std::size_t frames = 1;
  if (n->dim == 4) {
    const int k = n->axis[3].kind;
    if (k == nrrdKindList || k == nrrdKindTime || k == nrrdKindDomain || k == nrrdKindUnknown)
      frames = n->axis[3].size;
  }
  if (n->dim != 3 && n->dim != 4) {
    throw input_error(path, "expected a 3-D scalar volume, found " + std::to_string(n->dim) + "-D data (sizes " +
                                sizes_text(n) + ")");
  }
  if (n->dim == 4 && frames == 1 && n->axis[3].size != 1)
    throw input_error(path, std::string("expected a 3-D scalar volume or a sequence of them, found 4-D data (sizes ") +
                                sizes_text(n) + ") whose last axis (kind " + airEnumStr(nrrdKind, n->axis[3].kind) +
                                ") is not a list of frames");
  const auto t = scalar_type_of(n->type);
  if (!t) {
    throw input_error(path, std::string("unsupported NRRD type '") + airEnumStr(nrrdType, n->type) +
                                "' (expected a scalar integer or floating-point type)");
  }
  VolumeHeader h;
  h.type = *t;
  h.dims = {n->axis[0].size, n->axis[1].size, n->axis[2].size};
  h.frames = frames;
  for (unsigned ax = 0; ax < 3; ++ax) h.spacing[ax] = axis_spacing(n, ax);
  double origin[NRRD_SPACE_DIM_MAX];
  const unsigned sdim = nrrdSpaceOriginGet(n, origin);
  if (sdim > 0 && nrrdSpaceVecExists(sdim, origin)) {
    for (unsigned i = 0; i < 3; ++i) h.origin[i] = i < sdim ? origin[i] : 0.0;
  } else if (n->spaceDim == 0) {
    // No "space": fall back on per-axis mins, which for cell-centred axes
    // are the edge of the first voxel, not its centre.
    for (unsigned ax = 0; ax < 3; ++ax) {
      const double mn = n->axis[ax].min;
      if (!std::isfinite(mn)) continue;
      h.origin[ax] = n->axis[ax].center == nrrdCenterCell ? mn + h.spacing[ax] / 2 : mn;
    }
  }
  h.frame = frame_of(n);
  // "space units" (one per world axis, NRRD0004 and later): softshell works
  // in millimetres, so metres, centimetres and microns are scaled; the
  // unit of every axis must be the same length (an oblique axis mixes them).
  if (n->spaceDim > 0) {
    std::optional<double> scale;
    for (unsigned i = 0; i < n->spaceDim && i < NRRD_SPACE_DIM_MAX; ++i) {
      const char* u = n->spaceUnits[i];
      if (!u || !*u) continue;
      const std::optional<double> s = millimetres_per_unit(u);
      if (!s) throw input_error(path, std::string("space units: '") + u + "' not understood (expected mm, cm, m or um)");
      if (scale && *scale != *s) throw input_error(path, "space units differ between the world's axes");
      scale = s;
    }
    if (scale && *scale != 1.0) {
      for (int a = 0; a < 3; ++a) h.spacing[a] *= *scale, h.origin[a] *= *scale;
      h.frame.as_read.reset();  // the file's own vectors are in its unit
    }
  }
  check_geometry(path, h.spacing, h.origin);
  if (h.frame.as_read) h.frame.as_read->spacing = h.spacing;  // what the writer will compare with
  return h;
}

// ---- sizes, checked before Teem allocates ------------------------------------------

// Deflate's largest expansion is 1032:1 (zlib's technical details: a
// 258-byte match costs at least 2 bits); 1024 bytes of slack cover the gzip
// header and trailer.
constexpr std::uint64_t kMaxInflateRatio = 1032;

// What decompressing the stream at the current position of `f` gives, the
// output counted and dropped. It stops at an error, at the end of the
// stream once `needed` bytes came out, or `kPastNeeded` bytes past
// `needed` (Teem reads only what it needs; decoding a little further
// covers a stream that ends right there, whose checksum Teem verifies).
// gzip members that follow one another are followed while short of
// `needed`; bzip2, like Teem's reader, is one stream.
struct StreamCheck {
  std::uint64_t produced = 0;
  std::string error;  // empty: no error within what was decoded
  bool ended = false;  // the stream's end was decoded (checksum verified)
};
constexpr std::uint64_t kPastNeeded = 1 << 16;

StreamCheck check_gzip(std::FILE* f, std::uint64_t needed) {
  StreamCheck c;
  z_stream zs{};
  if (inflateInit2(&zs, 15 + 16) != Z_OK) return {0, "zlib initialisation failed"};  // gzip, as Teem reads it
  std::vector<unsigned char> in(1 << 16), out(1 << 16);
  bool done = false;
  while (!done) {
    zs.avail_in = static_cast<uInt>(std::fread(in.data(), 1, in.size(), f));
    zs.next_in = in.data();
    if (zs.avail_in == 0) break;  // the file ends
    while (zs.avail_in > 0 && !done) {
      zs.next_out = out.data();
      zs.avail_out = static_cast<uInt>(out.size());
      const int rc = inflate(&zs, Z_NO_FLUSH);
      c.produced += out.size() - zs.avail_out;
      if (rc == Z_STREAM_END) {
        c.ended = true;
        done = c.produced >= needed || inflateReset(&zs) != Z_OK;
        c.ended = done;  // another member follows: not ended yet
      } else if (rc != Z_OK && rc != Z_BUF_ERROR) {
        c.error = zs.msg ? zs.msg : "zlib error " + std::to_string(rc);
        done = true;
      }
      done = done || c.produced >= needed + kPastNeeded;
    }
  }
  inflateEnd(&zs);
  return c;
}

StreamCheck check_bzip2(std::FILE* f, std::uint64_t needed) {
  StreamCheck c;
  bz_stream bz{};
  if (BZ2_bzDecompressInit(&bz, 0, 0) != BZ_OK) return {0, "bzip2 initialisation failed"};
  std::vector<char> in(1 << 16), out(1 << 16);
  bool done = false;
  while (!done) {
    bz.avail_in = static_cast<unsigned>(std::fread(in.data(), 1, in.size(), f));
    bz.next_in = in.data();
    if (bz.avail_in == 0) break;
    while (bz.avail_in > 0 && !done) {
      bz.next_out = out.data();
      bz.avail_out = static_cast<unsigned>(out.size());
      const int rc = BZ2_bzDecompress(&bz);
      c.produced += out.size() - bz.avail_out;
      if (rc == BZ_STREAM_END) {
        c.ended = done = true;
      } else if (rc != BZ_OK) {
        c.error = "bzip2 error " + std::to_string(rc);
        done = true;
      }
      done = done || c.produced >= needed + kPastNeeded;
    }
  }
  BZ2_bzDecompressEnd(&bz);
  return c;
}

// Throws when the data cannot hold what the header declares: raw, hex and
// ascii against the bytes present, gzip against deflate's largest ratio,
// and compressed data by decompressing it once (output counted, not kept).
void check_data_size(const std::string& path, const HeaderScan& scan, const LoadInfo& info, const VolumeHeader& h) {
  const std::string& data = scan.data_file.empty() ? path : scan.data_file;
  FilePtr f = open_for_reading(data);
  const std::uint64_t total = file_size(f.get());
  const std::uint64_t start = scan.data_file.empty() ? scan.data_offset : 0;
  std::uint64_t avail = total > start ? total - start : 0;
  if (info.byte_skip > 0) avail = avail > std::uint64_t(info.byte_skip) ? avail - std::uint64_t(info.byte_skip) : 0;
  const std::uint64_t voxels = std::uint64_t(h.dims[0]) * h.dims[1] * h.dims[2] * h.frames;  // checked_voxels() ran
  const std::uint64_t expected = voxels * scalar_type_size(h.type);
  const std::string where = scan.data_file.empty() ? " after the header" : " in " + scan.data_file;
  const NrrdEncoding* e = info.encoding;
  auto truncated = [&](const std::string& what) { return input_error(path, "data truncated: " + what); };
  if (e == nrrdEncodingRaw) {
    if (avail < expected)
      throw truncated("expected " + std::to_string(expected) + " bytes of raw data, found " + std::to_string(avail) + where);
  } else if (e == nrrdEncodingHex) {
    if (avail / 2 < expected)
      throw truncated("expected " + std::to_string(expected) + " bytes as hex digits, found " + std::to_string(avail) +
                      " characters" + where);
  } else if (e == nrrdEncodingAscii) {
    if (avail < 2 * voxels - 1)  // a digit and a separator per sample at least
      throw truncated(std::to_string(voxels) + " ascii samples need at least " + std::to_string(2 * voxels - 1) +
                      " characters, found " + std::to_string(avail) + where);
  } else if (e == nrrdEncodingGzip || e == nrrdEncodingBzip2) {
    const bool gzip = e == nrrdEncodingGzip;
    // Teem skips "byte skip" bytes of the decompressed data; a negative one
    // makes it decompress everything into a buffer that grows without bound.
    if (info.byte_skip < 0)
      throw input_error(path, "byte skip " + std::to_string(info.byte_skip) + " is not supported with compressed data");
    const std::uint64_t total_avail = total > start ? total - start : 0;
    if (gzip && expected > kMaxInflateRatio * total_avail + 1024)
      throw truncated(std::to_string(total_avail) + " bytes of gzip data" + where + " cannot hold the " +
                      std::to_string(expected) + " bytes declared (gzip expands at most 1032-fold)");
    // Decompressed once, the output counted and dropped, before any buffer
    // of the declared size exists: a stream that is short or corrupt where
    // Teem reads it never reaches Teem (whose readers leak their state on
    // that path).
    if (std::fseek(f.get(), static_cast<long>(start), SEEK_SET) != 0)
      throw input_error(path, "cannot seek in " + data + ": " + std::strerror(errno));
    for (unsigned l = 0; l < info.line_skip; ++l) {
      int c;
      while ((c = std::fgetc(f.get())) != EOF && c != '\n') {
      }
    }
    const std::uint64_t needed = expected + std::uint64_t(info.byte_skip);
    const StreamCheck c = gzip ? check_gzip(f.get(), needed) : check_bzip2(f.get(), needed);
    if (!c.error.empty())
      throw input_error(path, std::string("corrupt ") + (gzip ? "gzip" : "bzip2") + " data after " +
                                  std::to_string(c.produced) + " bytes: " + c.error);
    if (c.produced < needed)
      throw input_error(path, "data truncated or corrupt: expected " + std::to_string(needed) +
                                  " bytes after decompression, found " + std::to_string(c.produced));
    // The samples are all there but the stream stops short of its end
    // (Teem's reader fails on that too).
    if (!c.ended && c.produced < needed + kPastNeeded)
      throw input_error(path, std::string("data truncated: the ") + (gzip ? "gzip" : "bzip2") +
                                  " stream ends without its end marker");
  } else {
    throw input_error(path, std::string("unsupported NRRD encoding '") + (e ? e->name : "unknown") +
                                "' (softshell reads raw, gzip, bzip2, ascii and hex)");
  }
}

// Header checks shared by read_nrrd and read_nrrd_header: everything but
// the samples. Call with the Teem mutex held.
VolumeHeader checked_header(const std::string& path) {
  const HeaderScan scan = scan_header(path);
  // Pass 1, header only: validate before Teem allocates anything.
  const NrrdOwned head(nrrdNew());
  const LoadInfo info = load(head.get(), path, true);
  VolumeHeader h = geometry(head.get(), path);
  checked_voxels(path, h.dims, h.type);
  // A sequence is read whole (Teem's reader), then one frame is kept.
  if (h.frames > 1) {
    if (h.frames > std::numeric_limits<std::size_t>::max() / std::max<std::size_t>(h.dims[2], 1))
      throw input_error(path, "sizes " + sizes_text(head.get()) + ": too many samples");
    checked_voxels(path, {h.dims[0], h.dims[1], h.dims[2] * h.frames}, h.type);
  }
  check_data_size(path, scan, info, h);
  h.files = {path};
  if (!scan.data_file.empty()) h.files.push_back(scan.data_file);
  return h;
}

}  // namespace

namespace {

// The frame a read takes: `frame`, which must exist; a sequence needs one.
std::size_t chosen_frame(const std::string& path, const VolumeHeader& h, std::optional<std::size_t> frame,
                         bool header_only) {
  const std::string range = h.frames == 1 ? "(0)" : "(0 to " + std::to_string(h.frames - 1) + ")";
  if (frame && *frame >= h.frames)
    throw input_error(path, "--frame " + std::to_string(*frame) + ": the file holds " + std::to_string(h.frames) +
                                (h.frames == 1 ? " frame " : " frames ") + range);
  if (!frame && h.frames > 1 && !header_only)
    throw input_error(path, "a sequence of " + std::to_string(h.frames) + " 3-D frames of " + dims_text(h.dims) +
                                ": choose one with --frame K " + range);
  return frame.value_or(0);
}

}  // namespace

VolumeHeader read_nrrd_header(const std::string& path, std::optional<std::size_t> frame, bool any_frame) {
  const std::lock_guard<std::mutex> lock(teem_mutex());
  nrrdStateVerboseIO = 0;  // Teem would otherwise chat on stderr
  VolumeHeader h = checked_header(path);
  chosen_frame(path, h, frame, any_frame);
  return h;
}

Volume read_nrrd(const std::string& path, std::optional<std::size_t> frame) {
  const std::lock_guard<std::mutex> lock(teem_mutex());
  nrrdStateVerboseIO = 0;  // Teem would otherwise chat on stderr
  const VolumeHeader h = checked_header(path);
  const std::size_t k = chosen_frame(path, h, frame, false);

  // Pass 2: the real thing.
  const NrrdOwned n(nrrdNew());
  load(n.get(), path, false);
  const unsigned dim = h.frames > 1 || n->dim == 4 ? 4u : 3u;
  if (n->dim != dim || n->type != nrrd_type_of(h.type) || n->axis[0].size != h.dims[0] ||
      n->axis[1].size != h.dims[1] || n->axis[2].size != h.dims[2] || (dim == 4 && n->axis[3].size != h.frames) ||
      !n->data) {
    throw input_error(path, "file changed while being read");
  }

  Volume v;
  v.dims = h.dims;
  v.source_type = h.type;
  v.spacing = h.spacing;
  v.origin = h.origin;
  v.frame = h.frame;
  v.data.resize(v.voxels());
  // After nrrdLoad the data is in host byte order.
  const std::size_t offset = k * v.voxels() * scalar_type_size(h.type);
  decode_samples(static_cast<const unsigned char*>(n->data) + offset, v.voxels(), h.type, false, v.data.data());
  return v;
}

std::vector<Volume> read_nrrd_frames(const std::string& path) {
  const std::lock_guard<std::mutex> lock(teem_mutex());
  nrrdStateVerboseIO = 0;
  const VolumeHeader h = checked_header(path);
  const NrrdOwned n(nrrdNew());
  load(n.get(), path, false);
  const unsigned dim = h.frames > 1 || n->dim == 4 ? 4u : 3u;
  if (n->dim != dim || n->type != nrrd_type_of(h.type) || n->axis[0].size != h.dims[0] ||
      n->axis[1].size != h.dims[1] || n->axis[2].size != h.dims[2] || (dim == 4 && n->axis[3].size != h.frames) ||
      !n->data) {
    throw input_error(path, "file changed while being read");
  }
  std::vector<Volume> frames(h.frames);
  for (std::size_t k = 0; k < h.frames; ++k) {
    Volume& v = frames[k];
    v.dims = h.dims;
    v.source_type = h.type;
    v.spacing = h.spacing;
    v.origin = h.origin;
    v.frame = h.frame;
    v.data.resize(v.voxels());
    const std::size_t offset = k * v.voxels() * scalar_type_size(h.type);
    decode_samples(static_cast<const unsigned char*>(n->data) + offset, v.voxels(), h.type, false, v.data.data());
  }
  return frames;
}

void write_nrrd(const std::string& path, const Volume& v, const WriteOptions& opt) {
  write_nrrd_frames(path, {&v}, opt);
}

void write_nrrd_frames(const std::string& path, const std::vector<const Volume*>& frames, const WriteOptions& opt) {
  const Volume& v = *frames.front();
  const ScalarType type = opt.type.value_or(v.source_type);
  const std::size_t count = frames.size();
  // Float samples of one frame are written as they are (Teem only reads the
  // wrapped data): no second copy of the volume. A sequence's frames are
  // laid end to end, frame slowest.
  std::vector<unsigned char> bytes;
  std::vector<float> joined;
  const std::vector<float>* all = &v.data;
  if (count > 1) {
    joined.reserve(v.data.size() * count);
    for (const Volume* f : frames) joined.insert(joined.end(), f->data.begin(), f->data.end());
    all = &joined;
  }
  if (type != ScalarType::Float32) bytes = encode_samples(*all, type);
  void* samples = type == ScalarType::Float32 ? const_cast<float*>(all->data()) : static_cast<void*>(bytes.data());

  AtomicFile out(path);
  {
    const std::lock_guard<std::mutex> lock(teem_mutex());
    nrrdStateVerboseIO = 0;
    const NrrdWrapper n(nrrdNew());
    const IoStatePtr nio(nrrdIoStateNew());
    if (!n || !nio) throw input_error(path, "out of memory");
    const int wrapped = count > 1 ? nrrdWrap_va(n.get(), samples, nrrd_type_of(type), 4u, v.dims[0], v.dims[1],
                                                v.dims[2], count)
                                  : nrrdWrap_va(n.get(), samples, nrrd_type_of(type), 3u, v.dims[0], v.dims[1],
                                                v.dims[2]);
    if (wrapped != 0) throw input_error(path, "cannot write: " + take_biff_message());
    // The volume's world: its own space when it names one Teem knows, else
    // left-posterior-superior (ITK's physical space, what MetaImage and
    // raw inputs mean), so 3D Slicer and ITK place it the same way.
    int space = nrrdSpaceLeftPosteriorSuperior;
    if (!v.frame.space.empty()) {
      space = airEnumVal(nrrdSpace, v.frame.space.c_str());
      if (space == nrrdSpaceUnknown || nrrdSpaceDimension(space) != 3)
        throw input_error(path, "cannot write: unknown 3-D space '" + v.frame.space + "'");
    }
    nrrdSpaceSet(n.get(), space);
    double dirs[3][NRRD_SPACE_DIM_MAX];
    for (int a = 0; a < 3; ++a) {
      nrrdSpaceVecSetNaN(dirs[a]);
      const auto& e = v.frame.as_read;
      const bool same = e && e->spacing[a] == v.spacing[a] && e->axes[a] == v.frame.axes[a];
      for (int c = 0; c < 3; ++c) dirs[a][c] = same ? e->directions[a][c] : v.spacing[a] * v.frame.axes[a][c];
    }
    double none[NRRD_SPACE_DIM_MAX];
    nrrdSpaceVecSetNaN(none);  // the frame axis has no direction in space
    if (count > 1)
      nrrdAxisInfoSet_va(n.get(), nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2], none);
    else
      nrrdAxisInfoSet_va(n.get(), nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
    if (v.frame.measurement_frame) {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) n->measurementFrame[i][j] = (*v.frame.measurement_frame)[i][j];
    }
    // A sequence's frame axis is a list (3D Slicer's Sequences module writes
    // and reads it so), labelled "frame".
    const int kinds[4] = {nrrdKindSpace, nrrdKindSpace, nrrdKindSpace, nrrdKindList};
    nrrdAxisInfoSet_nva(n.get(), nrrdAxisInfoKind, kinds);
    const int centers[4] = {nrrdCenterCell, nrrdCenterCell, nrrdCenterCell, nrrdCenterUnknown};
    nrrdAxisInfoSet_nva(n.get(), nrrdAxisInfoCenter, centers);
    if (count > 1) {
      airFree(n->axis[3].label);
      n->axis[3].label = airStrdup("frame");
    }
    double origin[NRRD_SPACE_DIM_MAX];
    nrrdSpaceVecSetNaN(origin);
    for (int c = 0; c < 3; ++c) origin[c] = v.origin[c];
    if (nrrdSpaceOriginSet(n.get(), origin) != 0)
      throw input_error(path, "cannot write: " + take_biff_message());
    // softshell's unit, stated (readers that honour it, 3D Slicer among
    // them, then need no convention).
    for (int c = 0; c < 3; ++c) {
      airFree(n->spaceUnits[c]);
      n->spaceUnits[c] = airStrdup("mm");
    }

    nrrdIoStateFormatSet(nio.get(), nrrdFormatNRRD);
    if (opt.compress) {
      nrrdIoStateEncodingSet(nio.get(), nrrdEncodingGzip);
      nrrdIoStateSet(nio.get(), nrrdIoStateZlibLevel, 6);
    } else {
      nrrdIoStateEncodingSet(nio.get(), nrrdEncodingRaw);
    }
    errno = 0;
    if (nrrdWrite(out.file(), n.get(), nio.get()) != 0) {
      // errno (e.g. ENOSPC) says more than Teem's "fwrite wrote only ...".
      const int err = errno;
      const std::string teem = take_biff_message();
      throw input_error(path, "cannot write: " + (err ? std::string(std::strerror(err)) : teem));
    }
  }
  out.commit();
}

}  // namespace softshell::io_detail
