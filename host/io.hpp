// Reading and writing volumes: NRRD (through Teem: raw, gzip, bzip2, ascii,
// attached or detached headers), MetaImage .mha/.mhd (hand-parsed, zlib for
// CompressedData), and headerless raw data with dimensions given by the user.
//
// Every failure throws InputError with a one-line "<path>: <problem>" message.
// Writes go to a temporary file in the target directory and are renamed into
// place only when complete, so a failed write leaves nothing behind.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "volume.hpp"

namespace softshell {

// Geometry and type of a headerless raw file (`--raw X,Y,Z --type T`).
struct RawSpec {
  Dims3 dims{0, 0, 0};
  ScalarType type = ScalarType::UInt8;
  Vec3d spacing{1.0, 1.0, 1.0};
  bool big_endian = false;
};

// Parses "X,Y,Z" into positive integers / positive reals; throws InputError
// naming `what` (the option) on malformed text.
Dims3 parse_dims(const std::string& text, const std::string& what);
Vec3d parse_vec3(const std::string& text, const std::string& what);

// Reads a 3-D scalar volume. With `raw`, the file is read as headerless raw
// data; otherwise the format is chosen by content (NRRD magic) and extension
// (.nrrd/.nhdr, .mha/.mhd). Checks, before allocating, that the voxel count
// does not overflow and that the samples fit in this machine's memory.
Volume read_volume(const std::string& path, const std::optional<RawSpec>& raw = std::nullopt);

struct WriteOptions {
  std::optional<ScalarType> type;  // default: the volume's source_type
  bool compress = false;           // gzip (NRRD) / zlib (MetaImage)
};

// Writes by extension: .nrrd (attached NRRD), .mha (MetaImage, data attached),
// .mhd (MetaImage header + detached .raw beside it). Integer output types
// round to nearest and clamp to the type's range. Throws InputError for an
// unknown extension or an unwritable place.
void write_volume(const std::string& path, const Volume& v, const WriteOptions& opt = {});

// Throws InputError if `output` names the same file as `input` (so a run
// can never clobber its own input).
void ensure_distinct_output(const std::string& input, const std::string& output);

// True if the memory needed for `voxels` samples (as float on the host) is
// available on this machine; used by the readers before allocating.
bool fits_in_memory(std::size_t voxels, std::size_t bytes_per_voxel);

// ---- Internal to the I/O layer (io.cpp, io_nrrd.cpp, io_metaimage.cpp) ----
namespace io_detail {

// Voxel count of `dims`; throws InputError naming `path` when the count (or
// its size in bytes) overflows, or when the float samples plus one file
// sample of type `t` per voxel would not fit in this machine's memory.
std::size_t checked_voxels(const std::string& path, const Dims3& dims, ScalarType t);

// Converts `n` samples of type `t` (byte-swapped first when `swap`) to float.
void decode_samples(const unsigned char* bytes, std::size_t n, ScalarType t, bool swap,
                    float* out);
// Encodes samples as type `t` in host byte order; integer types round to
// nearest and clamp to the type's range (NaN -> 0).
std::vector<unsigned char> encode_samples(const std::vector<float>& in, ScalarType t);
bool host_is_big_endian();

struct FileCloser {
  void operator()(std::FILE* f) const;
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;
// Opens an existing regular file for reading; throws InputError
// "<path>: cannot open: <strerror>" (a directory reads as EISDIR).
FilePtr open_for_reading(const std::string& path);
// Size in bytes of an open file.
std::uint64_t file_size(std::FILE* f);
// Reads up to `n` bytes; returns how many were read (fewer only at EOF).
// Throws InputError naming `path` on a read error.
std::size_t read_up_to(std::FILE* f, void* data, std::size_t n, const std::string& path);

// A temporary file ".<name>.tmp-XXXXXX" in the directory of `target`,
// renamed onto `target` by commit(); removed by the destructor if commit()
// was not reached, so a failed write leaves nothing behind.
class AtomicFile {
 public:
  explicit AtomicFile(std::string target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::FILE* file() const { return file_.get(); }
  const std::string& target() const { return target_; }
  // Writes all of `data`; throws InputError on a short write (e.g. ENOSPC).
  void write(const void* data, std::size_t n);
  // Flushes, syncs and closes the file, checking each step, then renames it.
  void commit();

 private:
  std::string target_, temp_;
  FilePtr file_;
  bool committed_ = false;
};

Volume read_nrrd(const std::string& path);
void write_nrrd(const std::string& path, const Volume& v, const WriteOptions& opt);
Volume read_metaimage(const std::string& path);
// `detached`: .mhd header plus "<stem>.raw" (".zraw" when compressed).
void write_metaimage(const std::string& path, const Volume& v, const WriteOptions& opt,
                     bool detached);

}  // namespace io_detail
}  // namespace softshell
