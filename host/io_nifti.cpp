// NIfTI-1 and NIfTI-2 reading (.nii, .nii.gz, .hdr + .img) through niftilib (Debian's
// libnifti2-dev), the format's reference library: it interprets the header (byte order, the
// qform quaternion, the sform matrix, dims and datatype). The bytes are read here, with
// zlib, so that every size the header declares is checked against the file before anything of
// that size is allocated (niftilib would allocate first and print its complaints on stderr);
// see docs/formats.md, "NIfTI".
#include <unistd.h>
#include <zlib.h>

#include <nifti2_io.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>

#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace softshell::io_detail {

namespace {

namespace fs = std::filesystem;

struct GzCloser {
  void operator()(gzFile_s* f) const { gzclose(f); }
};
using GzPtr = std::unique_ptr<gzFile_s, GzCloser>;
struct NimFree {
  void operator()(nifti_image* n) const { nifti_image_free(n); }
};
using NimPtr = std::unique_ptr<nifti_image, NimFree>;

// niftilib's options (debug level) are process-global.
std::mutex& nifti_mutex() {
  static std::mutex m;
  return m;
}

// Opens `path` through zlib: gzip data is decompressed, anything else read as it is.
// Regular files only (open_for_reading's rules); the descriptor is handed to zlib.
GzPtr open_gz(const std::string& path, bool& gzipped, std::uint64_t& size) {
  FilePtr f = open_for_reading(path);
  size = file_size(f.get());
  unsigned char magic[2] = {0, 0};
  gzipped = read_up_to(f.get(), magic, 2, path) == 2 && magic[0] == 0x1f && magic[1] == 0x8b;
  const int fd = ::dup(fileno(f.get()));
  if (fd < 0) throw input_error(path, std::string("cannot open: ") + std::strerror(errno));
  if (::lseek(fd, 0, SEEK_SET) != 0) {
    ::close(fd);
    throw input_error(path, std::string("cannot seek: ") + std::strerror(errno));
  }
  gzFile g = gzdopen(fd, "rb");
  if (!g) {
    ::close(fd);
    throw input_error(path, "cannot open: out of memory");
  }
  return GzPtr(g);
}

// Reads exactly `n` bytes (fewer only at the end of the data); throws on a zlib error.
std::size_t gz_read(gzFile g, void* out, std::size_t n, const std::string& path) {
  std::size_t done = 0;
  auto* p = static_cast<unsigned char*>(out);
  while (done < n) {
    const unsigned chunk = static_cast<unsigned>(std::min<std::size_t>(n - done, 1u << 30));
    const int got = gzread(g, p + done, chunk);
    if (got < 0) {
      int err = 0;
      const char* msg = gzerror(g, &err);
      throw input_error(path, std::string("corrupt gzip data: ") + (msg ? msg : "zlib error"));
    }
    if (got == 0) break;
    done += static_cast<std::size_t>(got);
  }
  return done;
}

std::optional<ScalarType> scalar_type_of(int dt) {
  switch (dt) {
    case DT_INT8: return ScalarType::Int8;
    case DT_UINT8: return ScalarType::UInt8;
    case DT_INT16: return ScalarType::Int16;
    case DT_UINT16: return ScalarType::UInt16;
    case DT_INT32: return ScalarType::Int32;
    case DT_UINT32: return ScalarType::UInt32;
    case DT_INT64: return ScalarType::Int64;
    case DT_UINT64: return ScalarType::UInt64;
    case DT_FLOAT32: return ScalarType::Float32;
    case DT_FLOAT64: return ScalarType::Float64;
    default: return std::nullopt;
  }
}

// Everything the header says, checked, and where the samples are.
struct NiftiInfo {
  VolumeHeader header;
  std::string data_path;          // the .nii itself or the .img beside a .hdr
  std::uint64_t data_offset = 0;  // vox_offset (in the decompressed stream)
  ScalarType file_type = ScalarType::UInt8;  // the stored samples' type (header.type is float when scaled)
  bool swap = false;              // samples in the other byte order
  double slope = 1.0, inter = 0.0;
  bool scaled = false;
};

NiftiInfo open_nifti(const std::string& path) {
  bool gz = false;
  std::uint64_t size = 0;
  GzPtr g = open_gz(path, gz, size);
  // The larger (NIfTI-2) header; a NIfTI-1 file uses its first 348 bytes.
  union {
    nifti_1_header h1;
    nifti_2_header h2;
    unsigned char bytes[sizeof(nifti_2_header)];
  } raw{};
  static_assert(sizeof(nifti_1_header) == 348 && sizeof(nifti_2_header) == 540, "NIfTI header sizes");
  const std::size_t got = gz_read(g.get(), raw.bytes, sizeof raw.bytes, path);
  std::int32_t sizeof_hdr = 0;
  std::memcpy(&sizeof_hdr, raw.bytes, 4);
  std::int32_t swapped = sizeof_hdr;
  nifti_swap_4bytes(1, &swapped);
  int version = 0;
  bool swap = false;
  for (const int v : {1, 2}) {
    const std::int32_t want = v == 1 ? 348 : 540;
    if (sizeof_hdr == want || swapped == want) version = v, swap = swapped == want && sizeof_hdr != want;
  }
  if (version == 0 || got < (version == 1 ? 348u : 540u))
    throw input_error(path, "not a NIfTI file (the header size is neither 348 nor 540 bytes)");
  const char* magic = version == 1 ? raw.h1.magic : raw.h2.magic;
  const bool one_file = magic[0] == 'n' && magic[1] == '+' && magic[2] == char('0' + version);
  const bool pair = magic[0] == 'n' && magic[1] == 'i' && magic[2] == char('0' + version);
  if (!one_file && !pair)
    throw input_error(path, version == 1 ? "no NIfTI magic (an Analyze 7.5 header?): its orientation is unknown; "
                                           "convert it to NIfTI or NRRD first"
                                         : "not a NIfTI-2 file (bad magic)");
  if (swap) {
    if (version == 1) nifti_swap_as_nifti1(&raw.h1);
    else nifti_swap_as_nifti2(&raw.h2);
  }

  // What niftilib's conversion would refuse with a message on stderr whatever its debug
  // level (datatype, dim[0], dim[1]) is refused here first.
  const std::int64_t dim0 = version == 1 ? raw.h1.dim[0] : raw.h2.dim[0];
  const std::int64_t dim1 = version == 1 ? raw.h1.dim[1] : raw.h2.dim[1];
  const int datatype = version == 1 ? raw.h1.datatype : raw.h2.datatype;
  if (dim0 < 1 || dim0 > 7)
    throw input_error(path, "invalid NIfTI-" + std::to_string(version) + " header: dim[0] = " + std::to_string(dim0) +
                                " (expected 1 to 7)");
  if (dim1 < 1)
    throw input_error(path, "invalid NIfTI-" + std::to_string(version) + " header: dim[1] = " + std::to_string(dim1));
  if (!scalar_type_of(datatype)) {
    throw input_error(path, std::string("unsupported NIfTI datatype '") + nifti_datatype_string(datatype) + "' (" +
                                std::to_string(datatype) + "; expected a scalar integer or floating-point type)");
  }

  // niftilib interprets the (now native-order) header: dims, datatype, the transforms.
  NimPtr nim;
  {
    const std::lock_guard<std::mutex> lock(nifti_mutex());
    nifti_set_debug_level(0);  // its complaints would go to stderr
    const int good = version == 1 ? nifti_hdr1_looks_good(&raw.h1) : nifti_hdr2_looks_good(&raw.h2);
    if (good) nim.reset(version == 1 ? nifti_convert_n1hdr2nim(raw.h1, nullptr) : nifti_convert_n2hdr2nim(raw.h2, nullptr));
  }
  if (!nim) {
    throw input_error(path, "invalid NIfTI-" + std::to_string(version) + " header (dim[0] = " + std::to_string(dim0) +
                                "; dims, datatype or sizes out of range)");
  }
  const nifti_image& n = *nim;

  // A 3-D scalar volume: dims 4..7 must be 1.
  std::string dims_text;
  for (int i = 1; i <= n.dim[0] && i <= 7; ++i) dims_text += (i > 1 ? " " : "") + std::to_string(n.dim[i]);
  for (int i = 4; i <= n.dim[0] && i <= 7; ++i) {
    if (n.dim[i] != 1) {
      throw input_error(path, "expected a 3-D scalar volume, found " + std::to_string(n.dim[0]) + "-D data (dims " +
                                  dims_text + (i == 4 ? "; a time series: softshell reads one 3-D frame per file" : "") +
                                  ")");
    }
  }
  Dims3 dims{1, 1, 1};  // a 1-D or 2-D image is a volume one voxel thick
  for (int i = 1; i <= 3 && i <= n.dim[0]; ++i) {
    if (n.dim[i] < 1) throw input_error(path, "dims " + dims_text + ": expected positive sizes");
    dims[i - 1] = static_cast<std::size_t>(n.dim[i]);
  }
  const auto type = scalar_type_of(n.datatype);
  if (!type) {
    throw input_error(path, std::string("unsupported NIfTI datatype '") + nifti_datatype_string(n.datatype) +
                                "' (expected a scalar integer or floating-point type)");
  }

  NiftiInfo info;
  VolumeHeader& h = info.header;
  h.type = *type;
  h.dims = dims;

  // Units of the grid: millimetres unless the header says metres or microns.
  const int units = XYZT_TO_SPACE(n.xyz_units);
  const double scale = units == NIFTI_UNITS_METER ? 1000.0 : units == NIFTI_UNITS_MICRON ? 1e-3 : 1.0;
  // The index-to-world transform: sform when its code is set, else qform (nibabel's order),
  // else the pixdims alone (NIfTI's "method 1": no orientation known).
  const nifti_dmat44* m = n.sform_code > 0 ? &n.sto_xyz : n.qform_code > 0 ? &n.qto_xyz : nullptr;
  bool placed = false;
  if (m) {
    Mat3 axes{};
    Vec3d spacing{};
    bool ok = true;
    for (int a = 0; a < 3 && ok; ++a) {
      const double c[3] = {m->m[0][a] * scale, m->m[1][a] * scale, m->m[2][a] * scale};
      const double len = std::sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
      ok = std::isfinite(len) && len > 0.0;
      spacing[a] = len;
      for (int r = 0; r < 3 && ok; ++r) axes[a][r] = c[r] / len;
    }
    const Vec3d origin{m->m[0][3] * scale, m->m[1][3] * scale, m->m[2][3] * scale};
    if (ok && std::fabs(determinant(axes)) > 1e-6) {
      h.spacing = spacing;
      h.origin = origin;
      h.frame.axes = axes;
      h.frame.space = "right-anterior-superior";  // NIfTI's world
      placed = true;
    }
  }
  if (!placed) {
    for (int a = 0; a < 3; ++a) {
      const double d = std::fabs(n.pixdim[a + 1]) * scale;
      h.spacing[a] = std::isfinite(d) && d > 0.0 ? d : 1.0;
    }
  }
  check_geometry(path, h.spacing, h.origin);
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(h.origin[a])) throw input_error(path, "origin is not finite");

  // Intensity scaling: applied unless the slope is 0 or not finite (NIfTI's rule) or it is
  // the identity; scaled data is float.
  if (std::isfinite(n.scl_slope) && n.scl_slope != 0.0 && std::isfinite(n.scl_inter) &&
      (n.scl_slope != 1.0 || n.scl_inter != 0.0)) {
    info.scaled = true;
    info.slope = n.scl_slope;
    info.inter = n.scl_inter;
  }
  info.swap = swap;
  info.file_type = h.type;

  const std::size_t voxels = checked_voxels(path, h.dims, h.type);
  const std::uint64_t expected = std::uint64_t(voxels) * scalar_type_size(h.type);
  if (info.scaled) h.type = ScalarType::Float32;  // what read_volume returns
  h.files = {path};
  info.data_path = path;
  if (one_file) {
    info.data_offset = static_cast<std::uint64_t>(n.iname_offset);
    if (info.data_offset < std::uint64_t(version == 1 ? 348 : 540))
      throw input_error(path, "vox_offset " + std::to_string(n.iname_offset) + " lies inside the header");
    if (!gz && size < info.data_offset + expected)
      throw input_error(path, "data truncated: expected " + std::to_string(expected) + " bytes from offset " +
                                  std::to_string(info.data_offset) + ", found " +
                                  std::to_string(size > info.data_offset ? size - info.data_offset : 0));
    if (gz && expected > 1032 * size + 1024)
      throw input_error(path, "data truncated: " + std::to_string(size) + " bytes of gzip data cannot hold the " +
                                  std::to_string(expected) + " bytes declared (gzip expands at most 1032-fold)");
  } else {
    // A .hdr/.img pair: the data file beside the header, same stem.
    fs::path p(path);
    std::string stem = p.filename().string();
    for (const char* ext : {".gz", ".hdr", ".nii"}) {
      if (stem.size() > std::strlen(ext) && lower(stem.substr(stem.size() - std::strlen(ext))) == ext)
        stem.resize(stem.size() - std::strlen(ext));
    }
    std::string name = stem + ".img";
    if (!fs::exists(p.parent_path() / name) && fs::exists(p.parent_path() / (name + ".gz"))) name += ".gz";
    info.data_path = resolve_data_file(path, name);
    h.files.push_back(info.data_path);
    info.data_offset = n.iname_offset > 0 ? static_cast<std::uint64_t>(n.iname_offset) : 0;
    bool data_gz = false;
    std::uint64_t data_size = 0;
    open_gz(info.data_path, data_gz, data_size);
    if (!data_gz && data_size < info.data_offset + expected)
      throw input_error(path, "data truncated: expected " + std::to_string(expected) + " bytes in " + info.data_path +
                                  ", found " + std::to_string(data_size > info.data_offset ? data_size - info.data_offset : 0));
    if (data_gz && expected > 1032 * data_size + 1024)
      throw input_error(path, "data truncated: " + info.data_path + " cannot hold the " + std::to_string(expected) +
                                  " bytes declared");
  }
  return info;
}

}  // namespace

VolumeHeader read_nifti_header(const std::string& path) { return open_nifti(path).header; }

Volume read_nifti(const std::string& path) {
  const NiftiInfo info = open_nifti(path);
  const VolumeHeader& h = info.header;
  bool gz = false;
  std::uint64_t size = 0;
  GzPtr g = open_gz(info.data_path, gz, size);
  if (info.data_offset > 0 && gzseek(g.get(), static_cast<z_off_t>(std::min<std::uint64_t>(info.data_offset, LONG_MAX)),
                                     SEEK_SET) < 0)
    throw input_error(path, "data truncated: the file ends before vox_offset " + std::to_string(info.data_offset));
  const std::size_t elem = scalar_type_size(info.file_type);
  Volume v(h.dims, h.spacing, h.type);
  v.origin = h.origin;
  v.frame = h.frame;
  // Decoded a chunk at a time: no second copy of the volume in file bytes.
  const std::size_t chunk = std::size_t(1) << 20;
  std::vector<unsigned char> bytes(std::min(v.voxels(), chunk) * elem);
  for (std::size_t done = 0; done < v.voxels();) {
    const std::size_t n = std::min(chunk, v.voxels() - done);
    const std::size_t got = gz_read(g.get(), bytes.data(), n * elem, path);
    if (got != n * elem) {
      throw input_error(path, "data truncated: expected " + std::to_string(v.voxels() * elem) + " bytes, found " +
                                  std::to_string(done * elem + got));
    }
    decode_samples(bytes.data(), n, info.file_type, info.swap, v.data.data() + done);
    done += n;
  }
  if (info.scaled)
    for (float& x : v.data) x = static_cast<float>(info.slope * double(x) + info.inter);
  return v;
}

// ---- writing -------------------------------------------------------------------

namespace {

int nifti_datatype_of(ScalarType t) {
  switch (t) {
    case ScalarType::Int8: return DT_INT8;
    case ScalarType::UInt8: return DT_UINT8;
    case ScalarType::Int16: return DT_INT16;
    case ScalarType::UInt16: return DT_UINT16;
    case ScalarType::Int32: return DT_INT32;
    case ScalarType::UInt32: return DT_UINT32;
    case ScalarType::Int64: return DT_INT64;
    case ScalarType::UInt64: return DT_UINT64;
    case ScalarType::Float32: return DT_FLOAT32;
    case ScalarType::Float64: return DT_FLOAT64;
  }
  return DT_FLOAT32;
}

}  // namespace

void write_nifti(const std::string& path, const Volume& v, const WriteOptions& opt, bool gzipped) {
  const ScalarType type = opt.type.value_or(v.source_type);
  nifti_1_header h{};
  h.sizeof_hdr = 348;
  h.dim[0] = 3;
  for (int a = 0; a < 3; ++a) {
    if (v.dims[a] > 32767) throw input_error(path, "cannot write NIfTI-1: an axis of " + std::to_string(v.dims[a]) +
                                                       " voxels is more than its 32767 (use .nrrd)");
    h.dim[a + 1] = static_cast<short>(v.dims[a]);
  }
  for (int a = 4; a < 8; ++a) h.dim[a] = 1;
  h.datatype = static_cast<short>(nifti_datatype_of(type));
  h.bitpix = static_cast<short>(8 * scalar_type_size(type));
  h.vox_offset = 352.0f;
  h.scl_slope = 0.0f;  // no intensity scaling: the samples are the values
  h.xyzt_units = NIFTI_UNITS_MM;
  std::memcpy(h.magic, "n+1\0", 4);
  std::snprintf(h.descrip, sizeof h.descrip, "softshell");

  // NIfTI's world is RAS. A patient space (LPS, RAS, LAS, or none named:
  // taken as LPS) is converted there, the same physical placement; another
  // space (scanner-xyz, 3D-right-handed) is written as it is, with the
  // sform code "aligned" rather than "scanner" (it names no patient frame).
  Vec3d origin = v.origin;
  WorldFrame frame = v.frame.to_lps(origin);
  const bool patient = frame.anatomical();
  if (patient) {
    for (Vec3d& a : frame.axes) a[0] = -a[0] + 0.0, a[1] = -a[1] + 0.0;
    origin[0] = -origin[0] + 0.0, origin[1] = -origin[1] + 0.0;
  }
  nifti_dmat44 m{};
  for (int r = 0; r < 3; ++r) {
    for (int a = 0; a < 3; ++a) m.m[r][a] = frame.axes[a][r] * v.spacing[a];
    m.m[r][3] = origin[r];
  }
  m.m[3][3] = 1.0;
  h.sform_code = h.qform_code = static_cast<short>(patient ? NIFTI_XFORM_SCANNER_ANAT : NIFTI_XFORM_ALIGNED_ANAT);
  for (int c = 0; c < 4; ++c) {
    h.srow_x[c] = static_cast<float>(m.m[0][c]);
    h.srow_y[c] = static_cast<float>(m.m[1][c]);
    h.srow_z[c] = static_cast<float>(m.m[2][c]);
  }
  // The qform (a rotation, a handedness and the spacings) of the same matrix.
  double qb, qc, qd, qx, qy, qz, dx, dy, dz, qfac;
  nifti_dmat44_to_quatern(m, &qb, &qc, &qd, &qx, &qy, &qz, &dx, &dy, &dz, &qfac);
  h.quatern_b = static_cast<float>(qb), h.quatern_c = static_cast<float>(qc), h.quatern_d = static_cast<float>(qd);
  h.qoffset_x = static_cast<float>(qx), h.qoffset_y = static_cast<float>(qy), h.qoffset_z = static_cast<float>(qz);
  h.pixdim[0] = static_cast<float>(qfac < 0 ? -1.0 : 1.0);
  for (int a = 0; a < 3; ++a) h.pixdim[a + 1] = static_cast<float>(v.spacing[a]);

  // Header, the 4-byte extension flag (none), then the samples, all in this
  // host's byte order (readers tell it from sizeof_hdr).
  std::vector<unsigned char> bytes(352, 0);
  std::memcpy(bytes.data(), &h, sizeof h);
  const std::vector<unsigned char> samples = encode_samples(v.data, type);
  bytes.insert(bytes.end(), samples.begin(), samples.end());
  if (gzipped) bytes = deflate_all(path, bytes, true);
  AtomicFile out(path);
  out.write(bytes.data(), bytes.size());
  out.commit();
}

}  // namespace softshell::io_detail
