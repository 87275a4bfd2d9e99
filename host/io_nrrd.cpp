// NRRD reading and writing through Teem, the format's reference
// implementation: every encoding Teem knows (raw, gzip, bzip2, ascii, hex)
// and detached headers (.nhdr) come for free. Teem reports errors through
// biff; they are turned into one-line InputErrors here.
#include <teem/nrrd.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <sstream>

#include "error.hpp"
#include "io.hpp"

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

// Loads `path` into `n`; header only when `header_only`.
void load(Nrrd* n, const std::string& path, bool header_only) {
  IoStatePtr nio(nrrdIoStateNew());
  if (!nio) throw input_error(path, "out of memory");
  if (header_only) nrrdIoStateSet(nio.get(), nrrdIoStateSkipData, AIR_TRUE);
  if (nrrdLoad(n, path.c_str(), nio.get()) != 0) throw input_error(path, take_biff_message());
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

}  // namespace

Volume read_nrrd(const std::string& path) {
  const std::lock_guard<std::mutex> lock(teem_mutex());
  nrrdStateVerboseIO = 0;  // Teem would otherwise chat on stderr

  // Pass 1, header only: validate before Teem allocates anything.
  Dims3 dims{};
  ScalarType type{};
  {
    const NrrdOwned head(nrrdNew());
    load(head.get(), path, true);
    if (head->dim != 3) {
      throw input_error(path, "expected a 3-D scalar volume, found " + std::to_string(head->dim) +
                                  "-D data (sizes " + sizes_text(head.get()) + ")");
    }
    const auto t = scalar_type_of(head->type);
    if (!t) {
      throw input_error(path, std::string("unsupported NRRD type '") +
                                  airEnumStr(nrrdType, head->type) +
                                  "' (expected a scalar integer or floating-point type)");
    }
    type = *t;
    dims = {head->axis[0].size, head->axis[1].size, head->axis[2].size};
    checked_voxels(path, dims, type);
  }

  // Pass 2: the real thing.
  const NrrdOwned n(nrrdNew());
  load(n.get(), path, false);
  if (n->dim != 3 || n->type != nrrd_type_of(type) || n->axis[0].size != dims[0] ||
      n->axis[1].size != dims[1] || n->axis[2].size != dims[2] || !n->data) {
    throw input_error(path, "file changed while being read");
  }

  Volume v;
  v.dims = dims;
  v.source_type = type;
  for (unsigned ax = 0; ax < 3; ++ax) v.spacing[ax] = axis_spacing(n.get(), ax);

  double origin[NRRD_SPACE_DIM_MAX];
  const unsigned sdim = nrrdSpaceOriginGet(n.get(), origin);
  if (sdim > 0 && nrrdSpaceVecExists(sdim, origin)) {
    for (unsigned i = 0; i < 3; ++i) v.origin[i] = i < sdim ? origin[i] : 0.0;
  } else if (n->spaceDim == 0) {
    // No "space": fall back on per-axis mins, which for cell-centred axes
    // are the edge of the first voxel, not its centre.
    for (unsigned ax = 0; ax < 3; ++ax) {
      const double mn = n->axis[ax].min;
      if (!std::isfinite(mn)) continue;
      v.origin[ax] = n->axis[ax].center == nrrdCenterCell ? mn + v.spacing[ax] / 2 : mn;
    }
  }

  v.data.resize(v.voxels());
  // After nrrdLoad the data is in host byte order.
  decode_samples(static_cast<const unsigned char*>(n->data), v.voxels(), type, false,
                 v.data.data());
  return v;
}

void write_nrrd(const std::string& path, const Volume& v, const WriteOptions& opt) {
  const ScalarType type = opt.type.value_or(v.source_type);
  std::vector<unsigned char> bytes = encode_samples(v.data, type);

  AtomicFile out(path);
  {
    const std::lock_guard<std::mutex> lock(teem_mutex());
    nrrdStateVerboseIO = 0;
    const NrrdWrapper n(nrrdNew());
    const IoStatePtr nio(nrrdIoStateNew());
    if (!n || !nio) throw input_error(path, "out of memory");
    if (nrrdWrap_va(n.get(), bytes.data(), nrrd_type_of(type), 3u, v.dims[0], v.dims[1],
                    v.dims[2]) != 0) {
      throw input_error(path, "cannot write: " + take_biff_message());
    }
    // A 3-D world space without anatomical claims: softshell does not track
    // patient orientation, only spacing and origin.
    nrrdSpaceSet(n.get(), nrrdSpace3DRightHanded);
    double dirs[3][NRRD_SPACE_DIM_MAX];
    for (int a = 0; a < 3; ++a) {
      nrrdSpaceVecSetNaN(dirs[a]);
      for (int c = 0; c < 3; ++c) dirs[a][c] = a == c ? v.spacing[a] : 0.0;
    }
    nrrdAxisInfoSet_va(n.get(), nrrdAxisInfoSpaceDirection, dirs[0], dirs[1], dirs[2]);
    const int kinds[3] = {nrrdKindSpace, nrrdKindSpace, nrrdKindSpace};
    nrrdAxisInfoSet_nva(n.get(), nrrdAxisInfoKind, kinds);
    const int centers[3] = {nrrdCenterCell, nrrdCenterCell, nrrdCenterCell};
    nrrdAxisInfoSet_nva(n.get(), nrrdAxisInfoCenter, centers);
    double origin[NRRD_SPACE_DIM_MAX];
    nrrdSpaceVecSetNaN(origin);
    for (int c = 0; c < 3; ++c) origin[c] = v.origin[c];
    if (nrrdSpaceOriginSet(n.get(), origin) != 0)
      throw input_error(path, "cannot write: " + take_biff_message());

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
