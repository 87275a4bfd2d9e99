// Volume I/O front end: format dispatch, the headerless raw reader, option
// parsing for --raw/--spacing, memory checks, sample conversion and the
// atomic (temp file + rename) writer shared by the NRRD and MetaImage code.
#include "io.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <mutex>
#include <sstream>
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

}  // namespace

namespace {

// A "Key:   123 kB" line of /proc/self/status, in bytes (0 if absent).
std::uint64_t proc_status_bytes(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string prefix = std::string(key) + ":";
  while (std::getline(in, line)) {
    if (line.rfind(prefix, 0) == 0) return std::strtoull(line.c_str() + prefix.size(), nullptr, 10) * 1024;
  }
  return 0;
}

std::uint64_t headroom(std::uint64_t limit, std::uint64_t used) { return limit > used ? limit - used : 0; }

}  // namespace

// Physical memory, lowered to a cgroup limit and to what the address-space
// and data-segment limits (ulimit -v, -d) leave this process: beyond those
// an allocation fails, and PoCL aborts on a failed allocation. The ulimits
// count what the process already holds (PoCL and LLVM map hundreds of MB of
// address space), so their headroom is the limit less the current use.
std::uint64_t usable_memory_bytes() {
  const long pages = sysconf(_SC_PHYS_PAGES);
  const long page = sysconf(_SC_PAGESIZE);
  std::uint64_t total = std::numeric_limits<std::uint64_t>::max();
  if (pages > 0 && page > 0 &&
      __builtin_mul_overflow(static_cast<std::uint64_t>(pages), static_cast<std::uint64_t>(page),
                             &total)) {
    total = std::numeric_limits<std::uint64_t>::max();
  }
  const std::pair<const char*, const char*> cgroups[] = {
      {"/sys/fs/cgroup/memory.max", ""}, {"/sys/fs/cgroup/memory/memory.limit_in_bytes", ""}};
  for (const auto& [max_file, current_file] : cgroups) {
    // The cgroup's own use counts reclaimable page cache (and every other
    // process in it): the limit alone is the fairer figure.
    (void)current_file;
    std::ifstream in(max_file);
    std::uint64_t limit = 0;
    if (in >> limit && limit > 0) total = std::min(total, limit);  // "max" fails to parse: no limit
  }
  const std::pair<int, const char*> rlimits[] = {{RLIMIT_AS, "VmSize"}, {RLIMIT_DATA, "VmData"}};
  for (const auto& [resource, key] : rlimits) {
    struct rlimit rl {};
    if (::getrlimit(resource, &rl) == 0 && rl.rlim_cur != RLIM_INFINITY)
      total = std::min<std::uint64_t>(total, headroom(rl.rlim_cur, proc_status_bytes(key)));
  }
  return total;
}

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

std::string special_file_kind(unsigned mode) {
  if (S_ISREG(mode)) return "";
  if (S_ISDIR(mode)) return "a directory";
  if (S_ISFIFO(mode)) return "a FIFO";
  if (S_ISCHR(mode)) return "a character device";
  if (S_ISBLK(mode)) return "a block device";
  if (S_ISSOCK(mode)) return "a socket";
  return "not a regular file";
}

FilePtr open_for_reading(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw input_error(path, "cannot open: " + errno_text(errno));
  // fopen() happily opens a directory for reading; fail here instead.
  if (S_ISDIR(st.st_mode)) throw input_error(path, "cannot open: " + errno_text(EISDIR));
  // A FIFO or a terminal would block or never end; a device has no size.
  if (!S_ISREG(st.st_mode))
    throw input_error(path, "cannot read " + special_file_kind(st.st_mode) + ": only regular files are read");
  // O_NONBLOCK: if the path was swapped for a FIFO since stat(), open() must
  // not wait for a writer; fstat() below then refuses it.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_NOCTTY | O_CLOEXEC);
  if (fd < 0) throw input_error(path, "cannot open: " + errno_text(errno));
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    const std::string kind = special_file_kind(st.st_mode);
    ::close(fd);
    throw input_error(path, "cannot read " + (kind.empty() ? std::string("it") : kind) + ": only regular files are read");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  FilePtr f(::fdopen(fd, "rb"));
  if (!f) {
    const int err = errno;
    ::close(fd);
    throw input_error(path, "cannot open: " + errno_text(err));
  }
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

std::string resolve_data_file(const std::string& header, const std::string& name) {
  const auto fail = [&](const std::string& problem) {
    return input_error(header, "data file " + name + ": " + problem);
  };
  if (name.empty()) throw input_error(header, "the data file name is empty");
  if (name == "-") throw fail("standard input is not read (name the data file)");
  const fs::path rel(name);
  const bool here = !fs::path(header).has_parent_path();
  const fs::path dir = here ? fs::path(".") : fs::path(header).parent_path();
  const fs::path full = rel.is_absolute() || here ? rel : dir / rel;
  struct stat st {};
  if (::stat(full.c_str(), &st) != 0) throw fail("cannot open: " + errno_text(errno));
  if (!S_ISREG(st.st_mode)) throw fail("is " + special_file_kind(st.st_mode) + ", not a regular file");
  const char* policy = std::getenv("SOFTSHELL_DATA_FILES");
  if (!(policy && std::string(policy) == "any")) {
    // Inside the header's directory tree, links followed: a header cannot
    // make softshell read /etc/shadow or another user's files as voxels.
    std::error_code e1, e2;
    const fs::path real_dir = fs::canonical(dir, e1), real = fs::canonical(full, e2);
    if (e1 || e2) throw fail("cannot resolve: " + (e1 ? e1 : e2).message());
    const auto mismatch = std::mismatch(real_dir.begin(), real_dir.end(), real.begin(), real.end());
    if (mismatch.first != real_dir.end())
      throw fail("lies outside the header's directory (" + real.string() +
                 "); set SOFTSHELL_DATA_FILES=any to allow it");
  }
  return full.string();
}

// ---- temporary files ---------------------------------------------------------

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

// The temporaries a signal handler must remove: fixed storage, written
// before a slot is marked used, so the handler only reads complete paths
// and calls nothing but unlink() and raise() (async-signal-safe).
constexpr int kTempSlots = 64;
struct TempSlot {
  std::atomic<bool> used{false};
  char path[PATH_MAX + 1] = {};
};
TempSlot g_temps[kTempSlots];
std::mutex g_temps_mutex;
// The signal being acted on (0: none), and how many threads are in a
// critical section: creating and registering a temporary, or renaming
// temporaries onto their targets. A signal waits for those (the thread
// leaving the section dies of it), so no temporary is created unseen and a
// .mhd pair is never left half replaced.
std::atomic<int> g_signal{0};
std::atomic<int> g_critical{0};
// The actions we replaced (the default, or a handler of a library: LLVM,
// inside PoCL, installs its own to remove its temporary files), restored
// and re-raised after ours ran, so both clean up.
struct sigaction g_previous[NSIG];

// Not instrumented by AddressSanitizer: before a call that does not return
// (_exit) ASan inserts __asan_handle_no_return, which reads the thread's
// stack bounds through pthread_getattr_np, which mallocs; in a signal
// handler that interrupted malloc that deadlocks on the allocator's lock
// (a classify interrupted by SIGINT hung so in the sanitized suite, once in
// three runs). These handlers only touch atomics and call async-signal-safe
// functions.
#define SOFTSHELL_SIGNAL_HANDLER __attribute__((no_sanitize("address", "undefined")))

[[noreturn]] SOFTSHELL_SIGNAL_HANDLER void remove_temporaries_and_die(int sig) {
  for (TempSlot& t : g_temps)
    if (t.used.load()) ::unlink(t.path);
  // Die of the same signal, so the parent sees what happened (inside the
  // handler the signal is blocked: unblock it for the previous action).
  ::sigaction(sig, &g_previous[sig], nullptr);
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, sig);
  ::pthread_sigmask(SIG_UNBLOCK, &set, nullptr);
  std::raise(sig);
  ::_exit(128 + sig);
}

extern "C" SOFTSHELL_SIGNAL_HANDLER void on_fatal_signal(int sig) {
  // The handler may run in any thread while others go on. Signal first,
  // then the count; a thread enters a section count first, then checks the
  // signal (both sequentially consistent): so either the handler sees the
  // thread in its section and leaves the dying to it, or the thread sees
  // the signal before it creates or renames anything.
  g_signal.store(sig);
  if (g_critical.load() == 0) remove_temporaries_and_die(sig);
}

// Dies of a signal that arrived while this thread could not act on it.
SOFTSHELL_SIGNAL_HANDLER void die_if_signalled() {
  if (const int sig = g_signal.load()) remove_temporaries_and_die(sig);
}

// Brackets a critical section (see g_critical).
class CriticalSection {
 public:
  CriticalSection() {
    g_critical.fetch_add(1);
    if (g_signal.load() != 0) {
      g_critical.fetch_sub(1);
      die_if_signalled();
    }
  }
  ~CriticalSection() {
    g_critical.fetch_sub(1);
    die_if_signalled();
  }
  CriticalSection(const CriticalSection&) = delete;
  CriticalSection& operator=(const CriticalSection&) = delete;
};

}  // namespace

void install_signal_cleanup() {
  static std::once_flag once;
  std::call_once(once, [] {
    // A write that exceeds RLIMIT_FSIZE then fails with EFBIG (one line,
    // exit 2) instead of killing the process with SIGXFSZ. (LLVM, inside
    // PoCL, may install a handler over it later; when it runs, it restores
    // this and returns, so the write still fails with EFBIG.)
    std::signal(SIGXFSZ, SIG_IGN);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
      // An ignored signal stays ignored (nohup, a background job's SIGINT).
      if (::sigaction(sig, nullptr, &g_previous[sig]) != 0 || g_previous[sig].sa_handler == SIG_IGN) continue;
      struct sigaction sa {};
      sa.sa_handler = on_fatal_signal;
      sigemptyset(&sa.sa_mask);
      for (int other : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&sa.sa_mask, other);
      ::sigaction(sig, &sa, nullptr);
    }
  });
}

namespace {

int register_temp(const std::string& path) {
  if (path.size() > PATH_MAX) return -1;
  const std::lock_guard<std::mutex> lock(g_temps_mutex);
  for (int i = 0; i < kTempSlots; ++i) {
    if (g_temps[i].used.load(std::memory_order_relaxed)) continue;
    std::memcpy(g_temps[i].path, path.c_str(), path.size() + 1);
    g_temps[i].used.store(true);
    return i;
  }
  return -1;  // more than 64 at once: still removed by the destructor or the next run
}

void unregister_temp(int slot) {
  if (slot < 0) return;
  const std::lock_guard<std::mutex> lock(g_temps_mutex);
  g_temps[slot].used.store(false);
}

// ".<name>.tmp-" followed by exactly mkstemp's six characters.
bool is_our_temp_name(const std::string& entry, const std::string& name) {
  const std::string prefix = "." + name + ".tmp-";
  if (entry.size() != prefix.size() + 6 || entry.compare(0, prefix.size(), prefix) != 0) return false;
  return std::all_of(entry.begin() + long(prefix.size()), entry.end(),
                     [](unsigned char c) { return std::isalnum(c) != 0; });
}

// Holds an flock() on a directory (released by the destructor).
class DirectoryLock {
 public:
  explicit DirectoryLock(const std::string& dir) : fd_(::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)) {
    if (fd_ < 0) throw input_error(dir, "cannot lock the directory: " + errno_text(errno));
    while (::flock(fd_, LOCK_EX) != 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      ::close(fd_);
      throw input_error(dir, "cannot lock the directory: " + errno_text(err));
    }
  }
  ~DirectoryLock() { ::close(fd_); }
  DirectoryLock(const DirectoryLock&) = delete;
  DirectoryLock& operator=(const DirectoryLock&) = delete;

 private:
  int fd_;
};

std::string directory_of(const std::string& target) {
  const fs::path t(target);
  return t.has_parent_path() ? t.parent_path().string() : std::string(".");
}

}  // namespace

std::size_t remove_stale_temporaries(const std::string& target, long max_age_seconds) {
  if (max_age_seconds < 0) max_age_seconds = AtomicFile::kStaleTempSeconds;
  const std::string dir = directory_of(target), name = fs::path(target).filename().string();
  DIR* d = ::opendir(dir.c_str());
  if (!d) return 0;
  std::size_t removed = 0;
  const std::time_t now = std::time(nullptr);
  while (const dirent* e = ::readdir(d)) {
    const std::string entry = e->d_name;
    if (!is_our_temp_name(entry, name)) continue;
    const std::string path = (fs::path(dir) / entry).string();
    // Our own (same owner), a regular file, not a link, and old.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) continue;
    struct stat st {};
    const bool candidate = ::fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && st.st_uid == ::geteuid() &&
                           now - st.st_mtime > max_age_seconds;
    // Unlocked: the writer that made it is gone (a live one holds its lock
    // until the rename, whatever its age).
    if (candidate && ::flock(fd, LOCK_EX | LOCK_NB) == 0 && ::unlink(path.c_str()) == 0) ++removed;
    ::close(fd);
  }
  ::closedir(d);
  return removed;
}

AtomicFile::AtomicFile(std::string target) : target_(std::move(target)) {
  const fs::path t(target_);
  const std::string name = t.filename().string();
  struct stat st {};
  if (name.empty() || name == "." || name == ".." ||
      (::stat(target_.c_str(), &st) == 0 && S_ISDIR(st.st_mode))) {
    throw input_error(target_, "cannot write: " + errno_text(EISDIR));
  }
  // Replacing /dev/full or a FIFO by a regular file (as root) would be
  // wrong, and writing into them is not what an output is.
  if (::stat(target_.c_str(), &st) == 0 && !S_ISREG(st.st_mode)) {
    throw input_error(target_, "cannot write: it is " + special_file_kind(st.st_mode) +
                                   "; outputs are regular files");
  }
  install_signal_cleanup();
  remove_stale_temporaries(target_);
  // Same directory as the target, so the final rename() cannot cross devices.
  const fs::path dir = directory_of(target_);
  std::string pattern = (dir / ("." + name + ".tmp-XXXXXX")).string();
  std::vector<char> buf(pattern.begin(), pattern.end());
  buf.push_back('\0');
  // Signals that clean up wait until the temporary is registered, so none
  // is left between its creation and its registration (in this thread they
  // are blocked; in the others, the handler defers to the section).
  int fd = -1, err = 0;
  {
    sigset_t block, old;
    sigemptyset(&block);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&block, sig);
    ::pthread_sigmask(SIG_BLOCK, &block, &old);
    {
      const CriticalSection section;
      fd = ::mkostemp(buf.data(), O_CLOEXEC);
      err = errno;
      if (fd >= 0) {
        temp_ = buf.data();
        slot_ = register_temp(temp_);
      }
      ::pthread_sigmask(SIG_SETMASK, &old, nullptr);
    }
  }
  if (fd < 0) throw input_error(target_, "cannot create file: " + errno_text(err));
  // Held until the fd closes: tells remove_stale_temporaries() we are alive.
  ::flock(fd, LOCK_EX | LOCK_NB);
  // mkstemp() makes the file 0600; give the output the usual permissions.
  ::fchmod(fd, 0666 & ~current_umask());
  file_.reset(::fdopen(fd, "wb"));
  if (!file_) {
    const int e = errno;
    ::close(fd);
    ::unlink(temp_.c_str());
    unregister_temp(slot_);
    throw input_error(target_, "cannot create file: " + errno_text(e));
  }
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    file_.reset();
    ::unlink(temp_.c_str());
  }
  unregister_temp(slot_);
}

void AtomicFile::write(const void* data, std::size_t n) {
  if (!file_) throw input_error(target_, "cannot write: file already closed");
  errno = 0;
  if (n > 0 && std::fwrite(data, 1, n, file_.get()) != n)
    throw input_error(target_, "cannot write: " + errno_text(errno ? errno : EIO));
}

void AtomicFile::finish() {
  if (!file_) throw input_error(target_, "cannot write: file already closed");
  // Buffered data hits the disk only here, so ENOSPC usually shows up here.
  // errno is not cleared first: when an earlier fwrite failed (ferror),
  // its errno (ENOSPC, EFBIG) is the one to report.
  if (std::fflush(file_.get()) != 0 || std::ferror(file_.get()))
    throw input_error(target_, "cannot write: " + errno_text(errno ? errno : EIO));
  if (::fsync(fileno(file_.get())) != 0 && errno != EINVAL && errno != EROFS)
    throw input_error(target_, "cannot write: " + errno_text(errno));
  // The flock() goes with the close; the file is complete by now.
  if (std::fclose(file_.release()) != 0)
    throw input_error(target_, "cannot write: " + errno_text(errno));
}

void AtomicFile::publish() {
  if (::rename(temp_.c_str(), target_.c_str()) != 0)
    throw input_error(target_, "cannot write: " + errno_text(errno));
  committed_ = true;
  unregister_temp(slot_);
  slot_ = -1;
}

void AtomicFile::commit() {
  finish();
  const CriticalSection section;
  publish();
}

void AtomicFile::commit_together(const std::vector<AtomicFile*>& files) {
  for (AtomicFile* f : files) f->finish();
  if (files.empty()) return;
  const DirectoryLock lock(directory_of(files.front()->target_));
  // SIGINT / SIGTERM wait until every file is renamed (or, if one came
  // before, none is).
  const CriticalSection section;
  for (AtomicFile* f : files) f->publish();
}

}  // namespace io_detail

// ---- raw ---------------------------------------------------------------------

namespace {

void check_raw_size(const std::string& path, const RawSpec& spec, std::uint64_t have) {
  const std::size_t voxels = io_detail::checked_voxels(path, spec.dims, spec.type);
  const std::uint64_t need = static_cast<std::uint64_t>(voxels) * scalar_type_size(spec.type);  // checked above
  if (have != need) {
    throw input_error(path, "file has " + std::to_string(have) + " bytes, but " + dims_text(spec.dims) + " " +
                                scalar_type_name(spec.type) + " needs " + std::to_string(need) + " bytes");
  }
}

Volume read_raw(const std::string& path, const RawSpec& spec) {
  io_detail::FilePtr f = io_detail::open_for_reading(path);
  check_raw_size(path, spec, io_detail::file_size(f.get()));
  check_geometry(path, spec.spacing, {0.0, 0.0, 0.0});
  Volume v(spec.dims, spec.spacing, spec.type);
  // Decoded a chunk at a time: no second copy of the volume in file bytes.
  const std::size_t elem = scalar_type_size(spec.type), chunk = (std::size_t(1) << 20);
  const bool swap = spec.big_endian != io_detail::host_is_big_endian();
  std::vector<unsigned char> bytes(std::min(v.voxels(), chunk) * elem);
  for (std::size_t done = 0; done < v.voxels();) {
    const std::size_t n = std::min(chunk, v.voxels() - done);
    const std::size_t got = io_detail::read_up_to(f.get(), bytes.data(), n * elem, path);
    if (got != n * elem) {
      throw input_error(path, "data truncated: expected " + std::to_string(v.voxels() * elem) + " bytes, found " +
                                  std::to_string(done * elem + got));
    }
    io_detail::decode_samples(bytes.data(), n, spec.type, swap, v.data.data() + done);
    done += n;
  }
  return v;
}

// NRRD by content (its magic) or extension, MetaImage, NIfTI and VTK ImageData by extension.
enum class Format { Nrrd, MetaImage, Nifti, Vti, Kretz, Dicom };
Format format_of(const std::string& path) {
  const auto dicom = [&] {
    if (!dicom_supported())
      throw input_error(path, "DICOM input is not part of this build (install libgdcm-dev and rebuild softshell)");
    return Format::Dicom;
  };
  // A folder is a DICOM series, unless its name says it is meant as another
  // format's file (then, as in a build without DICOM, "Is a directory").
  const std::string ext = extension_of(path);
  const bool other_name = ext == ".nrrd" || ext == ".nhdr" || ext == ".mha" || ext == ".mhd" || ext == ".nii" ||
                          ext == ".gz" || ext == ".hdr" || ext == ".vti" || ext == ".vol" || ext == ".raw";
  std::error_code ec;
  if (dicom_supported() && !other_name && fs::is_directory(path, ec)) return Format::Dicom;
  char magic[132] = {};
  std::size_t got = 0;
  {
    io_detail::FilePtr f = io_detail::open_for_reading(path);  // regular files only
    got = io_detail::read_up_to(f.get(), magic, sizeof magic, path);
  }
  // Content first: a NRRD file is a NRRD file whatever it is called; "DICM"
  // at byte 128 is DICOM's Part 10 file.
  if (std::memcmp(magic, "NRRD000", 7) == 0) return Format::Nrrd;
  if (got == sizeof magic && std::memcmp(magic + 128, "DICM", 4) == 0) return dicom();
  if (ext == ".nrrd" || ext == ".nhdr") return Format::Nrrd;
  if (ext == ".dcm" || ext == ".dicom") return dicom();
  if (ext == ".mha" || ext == ".mhd") return Format::MetaImage;
  if (ext == ".vti") return Format::Vti;
  if (std::memcmp(magic, "KRETZFIL", 8) == 0 || ext == ".vol") return Format::Kretz;
  const std::string name = lower(fs::path(path).filename().string());
  const bool nii_gz = name.size() > 7 && name.compare(name.size() - 7, 7, ".nii.gz") == 0;
  if (ext == ".nii" || ext == ".hdr" || nii_gz) {
    if (!nifti_supported())
      throw input_error(path, "NIfTI input is not part of this build (install libnifti2-dev and rebuild softshell)");
    return Format::Nifti;
  }
  throw input_error(path,
                    "unrecognised format (expected .nrrd, .nhdr, .mha, .mhd, .nii, .nii.gz, .hdr, .vti, .vol (Kretz), DICOM (.dcm or a series folder), or --raw X,Y,Z --type T)");
}

}  // namespace

// ---- tracked-frame sequences ------------------------------------------------------

namespace io_detail {

bool is_tracked_frame_key(const std::string& key) {
  if (key.rfind("Seq_Frame", 0) != 0) return false;
  std::size_t i = 9, digits = 0;
  unsigned long frame = 0;
  while (i < key.size() && std::isdigit(static_cast<unsigned char>(key[i])) && digits < 9) {
    frame = frame * 10 + static_cast<unsigned long>(key[i] - '0');
    ++i, ++digits;
  }
  if (digits == 0 || i >= key.size() || key[i] != '_') return false;
  const std::string name = key.substr(i + 1);
  return frame > 0 || name.find("Transform") != std::string::npos;
}

InputError tracked_frame_error(const std::string& path, const std::string& key) {
  std::string shown;
  for (char c : key.substr(0, 48)) shown += (static_cast<unsigned char>(c) >= 0x20 && c != 0x7f) ? c : '?';
  return input_error(path, "a PLUS tracked-frame sequence (2-D ultrasound frames, each with its own pose: key " +
                               shown +
                               "), not a 3-D volume; reconstruct a volume from it first (PLUS's VolumeReconstructor "
                               "or Slicer's SlicerIGT Volume Reconstruction) and classify that");
}

}  // namespace io_detail

// ---- geometry and samples ------------------------------------------------------

void check_geometry(const std::string& path, const Vec3d& spacing, const Vec3d& origin) {
  for (int a = 0; a < 3; ++a) {
    const double h = spacing[a];
    if (!(h >= kMinSpacingMm && h <= kMaxSpacingMm)) {
      std::ostringstream m;
      m << "spacing " << h << " mm along " << "xyz"[a] << " is outside [" << kMinSpacingMm << ", " << kMaxSpacingMm
        << "] mm (a wrong unit in the header?)";
      throw input_error(path, m.str());
    }
    if (!(std::fabs(origin[a]) <= kMaxOriginMm)) {
      std::ostringstream m;
      m << "origin " << origin[a] << " mm along " << "xyz"[a] << " is not within " << kMaxOriginMm << " mm of 0";
      throw input_error(path, m.str());
    }
  }
}

NonFiniteSamples find_non_finite(const Volume& v) {
  NonFiniteSamples r;
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    if (std::isfinite(v.data[i])) continue;
    if (r.count++ == 0) r.first = i;
  }
  return r;
}

void require_finite(const Volume& v, const std::string& path, const std::string& remedy) {
  const NonFiniteSamples nf = find_non_finite(v);
  if (nf.count == 0) return;
  const std::size_t i = nf.first, nx = v.dims[0], ny = v.dims[1];
  const float x = v.data[i];
  std::ostringstream m;
  m << "sample " << i << " (x " << i % nx << ", y " << (i / nx) % ny << ", z " << i / (nx * ny) << ") is "
    << (std::isnan(x) ? "NaN" : (x > 0 ? "+Inf" : "-Inf")) << "; " << nf.count << " of " << v.data.size()
    << " samples are not finite";
  if (!remedy.empty()) m << "; " << remedy;
  throw input_error(path, m.str());
}

std::size_t replace_non_finite(Volume& v, float value) {
  std::size_t n = 0;
  for (float& x : v.data)
    if (!std::isfinite(x)) x = value, ++n;
  return n;
}

// ---- dispatch ----------------------------------------------------------------

namespace {

// Only NRRD holds sequences; any other file is frame 0 of one.
void check_single_frame(const std::string& path, std::optional<std::size_t> frame) {
  if (frame && *frame != 0)
    throw input_error(path, "--frame " + std::to_string(*frame) + ": a 3-D volume has one frame (0)");
}

}  // namespace

Volume read_volume(const std::string& path, const std::optional<RawSpec>& raw, std::optional<std::size_t> frame) {
  if (raw) {
    check_single_frame(path, frame);
    return read_raw(path, *raw);
  }
  const Format f = format_of(path);
  if (f != Format::Nrrd && f != Format::Dicom) check_single_frame(path, frame);
  switch (f) {
    case Format::Dicom: return io_detail::read_dicom(path, frame);
    case Format::Nrrd: return io_detail::read_nrrd(path, frame);
    case Format::MetaImage: return io_detail::read_metaimage(path);
    case Format::Nifti: return io_detail::read_nifti(path);
    case Format::Vti: return io_detail::read_vti(path);
    case Format::Kretz: return io_detail::read_kretz(path);
  }
  return {};
}

#ifndef SOFTSHELL_HAVE_DICOM
bool dicom_supported() { return false; }
namespace io_detail {
Volume read_dicom(const std::string& path, std::optional<std::size_t>) {
  throw input_error(path, "DICOM input is not part of this build");
}
VolumeHeader read_dicom_header(const std::string& path, std::optional<std::size_t>, bool) {
  throw input_error(path, "DICOM input is not part of this build");
}
}  // namespace io_detail
#else
bool dicom_supported() { return true; }
#endif

#ifndef SOFTSHELL_HAVE_NIFTI
bool nifti_supported() { return false; }
namespace io_detail {
Volume read_nifti(const std::string& path) { throw input_error(path, "NIfTI input is not part of this build"); }
VolumeHeader read_nifti_header(const std::string& path) { throw input_error(path, "NIfTI input is not part of this build"); }
void write_nifti(const std::string& path, const Volume&, const WriteOptions&, bool) {
  throw input_error(path, "NIfTI output is not part of this build");
}
}  // namespace io_detail
#else
bool nifti_supported() { return true; }
#endif

VolumeHeader read_volume_header(const std::string& path, const std::optional<RawSpec>& raw,
                                std::optional<std::size_t> frame) {
  if (raw) {
    check_single_frame(path, frame);
    io_detail::FilePtr f = io_detail::open_for_reading(path);
    check_raw_size(path, *raw, io_detail::file_size(f.get()));
    check_geometry(path, raw->spacing, {0.0, 0.0, 0.0});
    VolumeHeader h;
    h.dims = raw->dims;
    h.type = raw->type;
    h.spacing = raw->spacing;
    h.files = {path};
    return h;
  }
  const Format f = format_of(path);
  if (f != Format::Nrrd && f != Format::Dicom) check_single_frame(path, frame);
  switch (f) {
    case Format::Dicom: return io_detail::read_dicom_header(path, frame, false);
    case Format::Nrrd: return io_detail::read_nrrd_header(path, frame, false);
    case Format::MetaImage: return io_detail::read_metaimage_header(path);
    case Format::Nifti: return io_detail::read_nifti_header(path);
    case Format::Vti: return io_detail::read_vti_header(path);
    case Format::Kretz: return io_detail::read_kretz_header(path);
  }
  return {};
}

namespace {

bool is_nii_gz(const std::string& path) {
  const std::string name = lower(fs::path(path).filename().string());
  return name.size() > 7 && name.compare(name.size() - 7, 7, ".nii.gz") == 0;
}

}  // namespace

bool is_volume_output(const std::string& path) {
  const std::string ext = extension_of(path);
  if (ext == ".nrrd" || ext == ".mha" || ext == ".mhd" || ext == ".vti") return true;
  return nifti_supported() && (ext == ".nii" || is_nii_gz(path));
}

std::string volume_output_extensions() {
  return nifti_supported() ? ".nrrd, .mha, .mhd, .nii, .nii.gz or .vti" : ".nrrd, .mha, .mhd or .vti";
}

void write_volume(const std::string& path, const Volume& v, const WriteOptions& opt) {
  const std::string ext = extension_of(path);
  if (!is_volume_output(path)) {
    throw input_error(path, "unsupported output extension '" + ext + "' (use " + volume_output_extensions() + ")");
  }
  if (v.data.size() != v.voxels() || v.voxels() == 0) {
    throw input_error(path, "cannot write: volume of dims " + dims_text(v.dims) + " holds " +
                                std::to_string(v.data.size()) + " samples");
  }
  if (ext == ".nrrd") {
    io_detail::write_nrrd(path, v, opt);
  } else if (ext == ".vti") {
    io_detail::write_vti(path, v, opt);
  } else if (ext == ".nii" || is_nii_gz(path)) {
    io_detail::write_nifti(path, v, opt, is_nii_gz(path));
  } else {
    io_detail::write_metaimage(path, v, opt, ext == ".mhd");
  }
}

std::vector<Volume> read_frames(const std::string& path) {
  const Format f = format_of(path);
  if (f == Format::Nrrd) return io_detail::read_nrrd_frames(path);
  if (f == Format::Dicom) {
    const std::size_t n = io_detail::read_dicom_header(path, std::nullopt, true).frames;
    std::vector<Volume> frames;
    for (std::size_t k = 0; k < n; ++k) frames.push_back(io_detail::read_dicom(path, n > 1 ? std::optional<std::size_t>(k) : std::nullopt));
    return frames;
  }
  std::vector<Volume> one;
  one.push_back(read_volume(path));
  return one;
}

void write_frames(const std::string& path, const std::vector<Volume>& frames, const WriteOptions& opt) {
  if (frames.empty()) throw input_error(path, "cannot write: no frames");
  if (frames.size() == 1) return write_volume(path, frames.front(), opt);
  if (extension_of(path) != ".nrrd")
    throw input_error(path, "a sequence of " + std::to_string(frames.size()) +
                                " frames is written as a 4-D NRRD only: use a .nrrd output");
  std::vector<const Volume*> list;
  for (const Volume& f : frames) {
    if (f.dims != frames.front().dims || f.data.size() != f.voxels() || f.voxels() == 0)
      throw input_error(path, "cannot write: the frames differ in dims (" + dims_text(f.dims) + " and " +
                                  dims_text(frames.front().dims) + ")");
    list.push_back(&f);
  }
  io_detail::write_nrrd_frames(path, list, opt);
}

// ---- input / output identity ---------------------------------------------------

std::vector<std::string> output_files(const std::string& path) {
  std::vector<std::string> files{path};
  // A .mhd output also writes "<stem>.raw" or "<stem>.zraw" beside it.
  if (extension_of(path) == ".mhd")
    for (const char* ext : {".raw", ".zraw"}) files.push_back(fs::path(path).replace_extension(ext).string());
  return files;
}

namespace {

// The files a read of `input` opens: its header's list when the header
// parses, else the path alone (the read itself will then fail, before any
// output is written).
std::vector<std::string> input_files(const std::string& input) {
  try {
    return read_any_header(input).files;
  } catch (const InputError&) {
    return {input};
  }
}

bool same_file(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  const bool ea = ::stat(a.c_str(), &sa) == 0, eb = ::stat(b.c_str(), &sb) == 0;
  if (ea && eb) return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
  if (ea != eb) return false;  // one exists, the other not: different files
  std::error_code ca_err, cb_err;
  const fs::path ca = fs::weakly_canonical(a, ca_err);
  const fs::path cb = fs::weakly_canonical(b, cb_err);
  if (ca_err || cb_err) return fs::path(a).lexically_normal() == fs::path(b).lexically_normal();
  return ca == cb;
}

}  // namespace

void ensure_distinct_outputs(const std::vector<std::string>& inputs, const std::vector<std::string>& outputs) {
  for (const std::string& input : inputs) {
    struct stat st {};
    if (input.empty() || ::stat(input.c_str(), &st) != 0) continue;
    const std::vector<std::string> read = input_files(input);
    for (const std::string& output : outputs) {
      for (const std::string& in : read) {
        for (const std::string& out : output_files(output)) {
          if (!same_file(in, out)) continue;
          if (in == input && out == output) throw input_error(output, "output would overwrite the input file");
          if (in == input)
            throw input_error(output, "output's data file " + out + " would overwrite the input file " + input);
          if (out == output)
            throw input_error(output, "output would overwrite " + in + ", the data file of the input " + input);
          throw input_error(output, "output's data file " + out + " would overwrite " + in +
                                        ", the data file of the input " + input);
        }
      }
    }
  }
}

void ensure_distinct_output(const std::string& input, const std::string& output) {
  ensure_distinct_outputs({input}, {output});
}

VolumeHeader read_any_header(const std::string& path, const std::optional<RawSpec>& raw) {
  if (!raw && format_of(path) == Format::Nrrd) return io_detail::read_nrrd_header(path, std::nullopt, true);
  if (!raw && format_of(path) == Format::Dicom) return io_detail::read_dicom_header(path, std::nullopt, true);
  return read_volume_header(path, raw);
}

}  // namespace softshell
