// Volume I/O front end: format dispatch, the headerless raw reader, option
// parsing for --raw/--spacing, memory checks, sample conversion and the
// atomic (temp file + rename) writer shared by the NRRD and MetaImage code.
#include "io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <type_traits>

#include "error.hpp"
#include "text.hpp"

namespace softshell {

namespace fs = std::filesystem;

namespace {

std::string errno_text(int err) { return err ? std::strerror(err) : "unknown error"; }

std::string extension_of(const std::string& path) {
  return lower(fs::path(path).extension().string());
}

// Splits "a,b,c" into exactly three trimmed fields; false otherwise.
bool split3(const std::string& text, std::string out[3]) {
  std::size_t start = 0;
  for (int i = 0; i < 3; ++i) {
    const std::size_t comma = text.find(',', start);
    if ((i < 2) != (comma != std::string::npos)) return false;
    out[i] = trim(text.substr(start, i < 2 ? comma - start : std::string::npos));
    if (out[i].empty()) return false;
    start = comma + 1;
  }
  return true;
}

// Physical memory, lowered to the cgroup limit when running in a container.
std::uint64_t usable_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGESIZE);
  std::uint64_t total = std::numeric_limits<std::uint64_t>::max();
  if (pages > 0 && page > 0 &&
      __builtin_mul_overflow(static_cast<std::uint64_t>(pages), static_cast<std::uint64_t>(page),
                             &total)) {
    total = std::numeric_limits<std::uint64_t>::max();
  }
  for (const char* f : {"/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"}) {
    std::ifstream in(f);
    std::uint64_t limit = 0;
    if (in >> limit && limit > 0) total = std::min(total, limit);  // "max" fails to parse
  }
  return total;
}

}  // namespace

// ---- option parsing ----------------------------------------------------------

Dims3 parse_dims(const std::string& text, const std::string& what) {
  const auto fail = [&] {
    return InputError(what + ": expected X,Y,Z with positive integers, got '" + text + "'");
  };
  std::string f[3];
  if (!split3(text, f)) throw fail();
  Dims3 d{};
  for (int i = 0; i < 3; ++i) {
    if (!std::all_of(f[i].begin(), f[i].end(), [](unsigned char c) { return std::isdigit(c); }))
      throw fail();
    errno = 0;
    char* end = nullptr;
    const unsigned long long v = std::strtoull(f[i].c_str(), &end, 10);
    if (errno == ERANGE || *end != '\0' || v == 0 ||
        v > std::numeric_limits<std::size_t>::max())
      throw fail();
    d[i] = static_cast<std::size_t>(v);
  }
  return d;
}

Vec3d parse_vec3(const std::string& text, const std::string& what) {
  const auto fail = [&] {
    return InputError(what + ": expected X,Y,Z with positive numbers, got '" + text + "'");
  };
  std::string f[3];
  if (!split3(text, f)) throw fail();
  Vec3d v{};
  for (int i = 0; i < 3; ++i) {
    errno = 0;
    char* end = nullptr;
    const double x = std::strtod(f[i].c_str(), &end);
    if (errno == ERANGE || *end != '\0' || !std::isfinite(x) || !(x > 0.0)) throw fail();
    v[i] = x;
  }
  return v;
}

// ---- memory ------------------------------------------------------------------

bool fits_in_memory(std::size_t voxels, std::size_t bytes_per_voxel) {
  std::size_t needed = 0;
  if (__builtin_mul_overflow(voxels, bytes_per_voxel, &needed)) return false;
  // Leave a quarter for the OS, the device runtime and the output volume.
  return static_cast<double>(needed) <= 0.75 * static_cast<double>(usable_memory_bytes());
}

namespace io_detail {

std::size_t checked_voxels(const std::string& path, const Dims3& dims, ScalarType t) {
  if (dims[0] == 0 || dims[1] == 0 || dims[2] == 0)
    throw input_error(path, "empty volume (dims " + dims_text(dims) + ")");
  std::size_t voxels = 0, bytes = 0;
  const std::size_t per_voxel = sizeof(float) + scalar_type_size(t);  // file bytes + floats
  if (__builtin_mul_overflow(dims[0], dims[1], &voxels) ||
      __builtin_mul_overflow(voxels, dims[2], &voxels) ||
      __builtin_mul_overflow(voxels, per_voxel, &bytes)) {
    throw input_error(path, "dims " + dims_text(dims) + " overflow the voxel count (too large for this machine)");
  }
  if (!fits_in_memory(voxels, per_voxel)) {
    throw input_error(path, "a " + dims_text(dims) + " " + scalar_type_name(t) + " volume needs " +
                                human_bytes(static_cast<double>(bytes)) +
                                " of memory, more than 75 % of this machine's " +
                                human_bytes(static_cast<double>(usable_memory_bytes())));
  }
  return voxels;
}

bool host_is_big_endian() {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  return true;
#else
  return false;
#endif
}

// ---- sample conversion -------------------------------------------------------

namespace {

template <typename T>
void decode_as(const unsigned char* bytes, std::size_t n, bool swap, float* out) {
  unsigned char tmp[sizeof(T)];
  for (std::size_t i = 0; i < n; ++i) {
    std::memcpy(tmp, bytes + i * sizeof(T), sizeof(T));
    if (swap) std::reverse(tmp, tmp + sizeof(T));
    T v;
    std::memcpy(&v, tmp, sizeof(T));
    out[i] = static_cast<float>(v);
  }
}

template <typename T>
T convert_sample(float x) {
  if constexpr (std::is_floating_point_v<T>) {
    return static_cast<T>(x);
  } else {
    if (std::isnan(x)) return 0;
    const double r = std::round(static_cast<double>(x));
    // Both bounds are exact in double: lowest() is 0 or -2^k, max()+1 is 2^k.
    const double lo = static_cast<double>(std::numeric_limits<T>::lowest());
    const double hi_excl = std::ldexp(1.0, std::numeric_limits<T>::digits);
    if (r <= lo) return std::numeric_limits<T>::lowest();
    if (r >= hi_excl) return std::numeric_limits<T>::max();
    return static_cast<T>(r);
  }
}

template <typename T>
void encode_as(const std::vector<float>& in, unsigned char* out) {
  for (std::size_t i = 0; i < in.size(); ++i) {
    const T v = convert_sample<T>(in[i]);
    std::memcpy(out + i * sizeof(T), &v, sizeof(T));
  }
}

}  // namespace

void decode_samples(const unsigned char* bytes, std::size_t n, ScalarType t, bool swap,
                    float* out) {
  switch (t) {
    case ScalarType::Int8: return decode_as<std::int8_t>(bytes, n, false, out);
    case ScalarType::UInt8: return decode_as<std::uint8_t>(bytes, n, false, out);
    case ScalarType::Int16: return decode_as<std::int16_t>(bytes, n, swap, out);
    case ScalarType::UInt16: return decode_as<std::uint16_t>(bytes, n, swap, out);
    case ScalarType::Int32: return decode_as<std::int32_t>(bytes, n, swap, out);
    case ScalarType::UInt32: return decode_as<std::uint32_t>(bytes, n, swap, out);
    case ScalarType::Int64: return decode_as<std::int64_t>(bytes, n, swap, out);
    case ScalarType::UInt64: return decode_as<std::uint64_t>(bytes, n, swap, out);
    case ScalarType::Float32: return decode_as<float>(bytes, n, swap, out);
    case ScalarType::Float64: return decode_as<double>(bytes, n, swap, out);
  }
}

std::vector<unsigned char> encode_samples(const std::vector<float>& in, ScalarType t) {
  std::vector<unsigned char> out(in.size() * scalar_type_size(t));
  switch (t) {
    case ScalarType::Int8: encode_as<std::int8_t>(in, out.data()); break;
    case ScalarType::UInt8: encode_as<std::uint8_t>(in, out.data()); break;
    case ScalarType::Int16: encode_as<std::int16_t>(in, out.data()); break;
    case ScalarType::UInt16: encode_as<std::uint16_t>(in, out.data()); break;
    case ScalarType::Int32: encode_as<std::int32_t>(in, out.data()); break;
    case ScalarType::UInt32: encode_as<std::uint32_t>(in, out.data()); break;
    case ScalarType::Int64: encode_as<std::int64_t>(in, out.data()); break;
    case ScalarType::UInt64: encode_as<std::uint64_t>(in, out.data()); break;
    case ScalarType::Float32: encode_as<float>(in, out.data()); break;
    case ScalarType::Float64: encode_as<double>(in, out.data()); break;
  }
  return out;
}

// ---- files -------------------------------------------------------------------

void FileCloser::operator()(std::FILE* f) const {
  if (f) std::fclose(f);
}

FilePtr open_for_reading(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw input_error(path, "cannot open: " + errno_text(errno));
  // fopen() happily opens a directory for reading; fail here instead.
  if (S_ISDIR(st.st_mode)) throw input_error(path, "cannot open: " + errno_text(EISDIR));
  FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) throw input_error(path, "cannot open: " + errno_text(errno));
  return f;
}

std::uint64_t file_size(std::FILE* f) {
  struct stat st {};
  if (::fstat(fileno(f), &st) != 0) return 0;
  return static_cast<std::uint64_t>(st.st_size);
}

std::size_t read_up_to(std::FILE* f, void* data, std::size_t n, const std::string& path) {
  const std::size_t got = std::fread(data, 1, n, f);
  if (got < n && std::ferror(f)) throw input_error(path, "read error: " + errno_text(errno));
  return got;
}

namespace {

mode_t current_umask() {
  // Read it from /proc: calling umask() to query it would briefly change it
  // for every thread of the process.
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("Umask:", 0) == 0) return static_cast<mode_t>(std::strtoul(line.c_str() + 6, nullptr, 8));
  }
  return 022;
}

}  // namespace

AtomicFile::AtomicFile(std::string target) : target_(std::move(target)) {
  const fs::path t(target_);
  const std::string name = t.filename().string();
  struct stat st {};
  if (name.empty() || name == "." || name == ".." ||
      (::stat(target_.c_str(), &st) == 0 && S_ISDIR(st.st_mode))) {
    throw input_error(target_, "cannot write: " + errno_text(EISDIR));
  }
  // Same directory as the target, so the final rename() cannot cross devices.
  const fs::path dir = t.has_parent_path() ? t.parent_path() : fs::path(".");
  std::string pattern = (dir / ("." + name + ".tmp-XXXXXX")).string();
  std::vector<char> buf(pattern.begin(), pattern.end());
  buf.push_back('\0');
  const int fd = ::mkstemp(buf.data());
  if (fd < 0) throw input_error(target_, "cannot create file: " + errno_text(errno));
  temp_ = buf.data();
  // mkstemp() makes the file 0600; give the output the usual permissions.
  ::fchmod(fd, 0666 & ~current_umask());
  file_.reset(::fdopen(fd, "wb"));
  if (!file_) {
    const int err = errno;
    ::close(fd);
    ::unlink(temp_.c_str());
    throw input_error(target_, "cannot create file: " + errno_text(err));
  }
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    file_.reset();
    ::unlink(temp_.c_str());
  }
}

void AtomicFile::write(const void* data, std::size_t n) {
  if (!file_) throw input_error(target_, "cannot write: file already closed");
  errno = 0;
  if (n > 0 && std::fwrite(data, 1, n, file_.get()) != n)
    throw input_error(target_, "cannot write: " + errno_text(errno ? errno : EIO));
}

void AtomicFile::commit() {
  if (!file_) throw input_error(target_, "cannot write: file already closed");
  // Buffered data hits the disk only here, so ENOSPC usually shows up here.
  if (std::fflush(file_.get()) != 0 || std::ferror(file_.get()))
    throw input_error(target_, "cannot write: " + errno_text(errno ? errno : EIO));
  if (::fsync(fileno(file_.get())) != 0 && errno != EINVAL && errno != EROFS)
    throw input_error(target_, "cannot write: " + errno_text(errno));
  if (std::fclose(file_.release()) != 0)
    throw input_error(target_, "cannot write: " + errno_text(errno));
  if (::rename(temp_.c_str(), target_.c_str()) != 0)
    throw input_error(target_, "cannot write: " + errno_text(errno));
  committed_ = true;
}

}  // namespace io_detail

// ---- raw ---------------------------------------------------------------------

namespace {

Volume read_raw(const std::string& path, const RawSpec& spec) {
  io_detail::FilePtr f = io_detail::open_for_reading(path);
  const std::size_t voxels = io_detail::checked_voxels(path, spec.dims, spec.type);
  const std::size_t elem = scalar_type_size(spec.type);
  const std::uint64_t need = static_cast<std::uint64_t>(voxels) * elem;  // checked above
  const std::uint64_t have = io_detail::file_size(f.get());
  if (have != need) {
    throw input_error(path, "file has " + std::to_string(have) + " bytes, but " +
                                dims_text(spec.dims) + " " + scalar_type_name(spec.type) +
                                " needs " + std::to_string(need) + " bytes");
  }
  std::vector<unsigned char> bytes(static_cast<std::size_t>(need));
  const std::size_t got = io_detail::read_up_to(f.get(), bytes.data(), bytes.size(), path);
  if (got != bytes.size()) {
    throw input_error(path, "data truncated: expected " + std::to_string(need) +
                                " bytes, found " + std::to_string(got));
  }
  Volume v(spec.dims, spec.spacing, spec.type);
  io_detail::decode_samples(bytes.data(), voxels, spec.type,
                            spec.big_endian != io_detail::host_is_big_endian(), v.data.data());
  return v;
}

}  // namespace

// ---- dispatch ----------------------------------------------------------------

Volume read_volume(const std::string& path, const std::optional<RawSpec>& raw) {
  if (raw) return read_raw(path, *raw);

  char magic[8] = {};
  {
    io_detail::FilePtr f = io_detail::open_for_reading(path);
    io_detail::read_up_to(f.get(), magic, sizeof magic, path);
  }
  const std::string ext = extension_of(path);
  // Content first: a NRRD file is a NRRD file whatever it is called.
  if (std::memcmp(magic, "NRRD000", 7) == 0 || ext == ".nrrd" || ext == ".nhdr")
    return io_detail::read_nrrd(path);
  if (ext == ".mha" || ext == ".mhd") return io_detail::read_metaimage(path);
  throw input_error(path,
                    "unrecognised format (expected .nrrd, .nhdr, .mha, .mhd, or --raw X,Y,Z --type T)");
}

void write_volume(const std::string& path, const Volume& v, const WriteOptions& opt) {
  const std::string ext = extension_of(path);
  if (ext != ".nrrd" && ext != ".mha" && ext != ".mhd") {
    throw input_error(path, "unsupported output extension '" + ext + "' (use .nrrd, .mha or .mhd)");
  }
  if (v.data.size() != v.voxels() || v.voxels() == 0) {
    throw input_error(path, "cannot write: volume of dims " + dims_text(v.dims) + " holds " +
                                std::to_string(v.data.size()) + " samples");
  }
  if (ext == ".nrrd") {
    io_detail::write_nrrd(path, v, opt);
  } else {
    io_detail::write_metaimage(path, v, opt, ext == ".mhd");
  }
}

namespace {

bool same_file(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  if (::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0)
    return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  std::error_code ea, eb;
  const fs::path ca = fs::weakly_canonical(a, ea);
  const fs::path cb = fs::weakly_canonical(b, eb);
  if (ea || eb) return fs::path(a).lexically_normal() == fs::path(b).lexically_normal();
  return ca == cb;
}

}  // namespace

void ensure_distinct_output(const std::string& input, const std::string& output) {
  if (same_file(input, output)) throw input_error(output, "output would overwrite the input file");
  // A .mhd output also writes "<stem>.raw" or "<stem>.zraw" beside it.
  if (extension_of(output) == ".mhd") {
    for (const char* ext : {".raw", ".zraw"}) {
      const std::string data = fs::path(output).replace_extension(ext).string();
      if (same_file(input, data)) {
        throw input_error(output, "output's data file " + data + " would overwrite the input file");
      }
    }
  }
}

}  // namespace softshell
