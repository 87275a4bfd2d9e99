// Reading and writing volumes: NRRD (through Teem: raw, gzip, bzip2, ascii,
// attached or detached headers), MetaImage .mha/.mhd (hand-parsed, zlib for
// CompressedData), and headerless raw data with dimensions given by the user.
//
// Every failure throws InputError with a one-line "<path>: <problem>" message.
// Writes go to a temporary file in the target directory and are renamed into
// place only when complete, so a failed write leaves nothing behind.
//
// Hostile or careless input (docs/formats.md, "What the readers refuse"):
// only regular files are read (no FIFO, device or standard input, which would
// block or never end); a header's detached data file must lie in the header's
// own directory tree unless SOFTSHELL_DATA_FILES=any; every size a header
// declares is checked against the bytes the file holds before anything that
// size is allocated, and decompression never produces more than the header
// declares.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "error.hpp"
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
// (.nrrd/.nhdr, .mha/.mhd, .nii/.nii.gz/.hdr, .vti). Checks, before allocating, that the voxel count
// does not overflow, that the samples fit in this machine's memory and that
// the file holds the bytes its header declares.
//
// 3D+t: a 4-D NRRD whose slowest axis holds frames (kind list, time or
// domain, as 3D Slicer's Sequences module writes them) is a sequence of 3-D
// volumes of one geometry; `frame` picks one (0-based). Without it such a
// file is refused with one line giving the frame count; a 3-D file is frame 0.
Volume read_volume(const std::string& path, const std::optional<RawSpec>& raw = std::nullopt,
                   std::optional<std::size_t> frame = std::nullopt);

// 3D+t: every frame of `path` (a 3-D file of any format is one frame), read
// once. Throws InputError like read_volume.
std::vector<Volume> read_frames(const std::string& path);

// True when this build reads DICOM (.dcm files and series folders; GDCM was found).
bool dicom_supported();

// True when this build reads NIfTI (.nii, .nii.gz, .hdr/.img; niftilib was found).
bool nifti_supported();

// A volume file's header: what read_volume() would return, without the
// samples, and the files a read opens.
struct VolumeHeader {
  Dims3 dims{0, 0, 0};
  ScalarType type = ScalarType::UInt8;
  Vec3d spacing{1.0, 1.0, 1.0};
  Vec3d origin{0.0, 0.0, 0.0};
  WorldFrame frame;
  std::vector<std::string> files;  // the header itself, then its detached data file(s)
  std::size_t frames = 1;          // > 1: a 3D+t sequence (dims are one frame's)
};
// Parses the header only (and checks that its data files are acceptable);
// allocates nothing of the volume's size. Throws InputError like read_volume.
// `frame` as for read_volume (the chosen frame's header, `frames` the count;
// a sequence without a frame chosen is refused the same way).
VolumeHeader read_volume_header(const std::string& path, const std::optional<RawSpec>& raw = std::nullopt,
                                std::optional<std::size_t> frame = std::nullopt);
// The header of any file, a sequence without a frame chosen included
// (frames > 1; dims, spacing, ... are each frame's): what `info` shows.
VolumeHeader read_any_header(const std::string& path, const std::optional<RawSpec>& raw = std::nullopt);

// Voxel spacing softshell accepts, in mm: 1 nm to 1 km. Outside it the
// header's unit is wrong (or the file is corrupt), and the float32 grid
// arithmetic on the device would over- or underflow. The origin must lie
// within 1e9 mm of 0 for the same reason.
inline constexpr double kMinSpacingMm = 1e-6, kMaxSpacingMm = 1e6, kMaxOriginMm = 1e9;
// Throws InputError naming `path` when spacing or origin is outside those
// limits or not finite.
void check_geometry(const std::string& path, const Vec3d& spacing, const Vec3d& origin);

// Non-finite samples (NaN, +-Inf): how many, and the first one's index.
struct NonFiniteSamples {
  std::size_t count = 0;
  std::size_t first = 0;  // valid when count > 0
};
NonFiniteSamples find_non_finite(const Volume& v);
// Throws InputError "<path>: sample N (x, y, z) is nan; ..." when `v` holds a
// non-finite sample; `remedy` ends the message (e.g. the option that
// replaces them).
void require_finite(const Volume& v, const std::string& path, const std::string& remedy);
// Replaces every non-finite sample by `value`; returns how many.
std::size_t replace_non_finite(Volume& v, float value);

struct WriteOptions {
  std::optional<ScalarType> type;  // default: the volume's source_type
  bool compress = false;           // gzip (NRRD) / zlib (MetaImage)
};

// Writes by extension: .nrrd (attached NRRD), .mha (MetaImage, data attached),
// .mhd (MetaImage header + detached .raw beside it), .nii / .nii.gz (NIfTI-1,
// when nifti_supported()), .vti (VTK XML ImageData). Integer output types
// round to nearest and clamp to the type's range. Throws InputError for an
// unknown extension or an unwritable place.
void write_volume(const std::string& path, const Volume& v, const WriteOptions& opt = {});
// Writes `frames` (one geometry, at least one) as a 4-D NRRD sequence (one
// frame: the 3-D file write_volume writes). Only .nrrd holds a sequence:
// another extension is an InputError naming the path; so are frames of
// different dims.
void write_frames(const std::string& path, const std::vector<Volume>& frames, const WriteOptions& opt = {});
// True when write_volume knows the path's extension; the list for messages.
bool is_volume_output(const std::string& path);
std::string volume_output_extensions();  // ".nrrd, .mha, .mhd, .nii, .nii.gz or .vti"

// The files write_volume(path) creates or replaces: `path`, and for .mhd its
// data file ("<stem>.raw", or "<stem>.zraw" when compressed: both listed).
std::vector<std::string> output_files(const std::string& path);

// Throws InputError if writing `output` would replace any file that reading
// `input` opens: the input itself and its detached data files, compared by
// device and inode (any spelling, hard and symbolic links), against every
// file the output writes (output_files). So a run never clobbers its input.
void ensure_distinct_output(const std::string& input, const std::string& output);
// The same for several inputs (volume, mask, initial guess, ...) and several
// outputs (turntable frames, ...). Inputs that do not exist are skipped.
void ensure_distinct_outputs(const std::vector<std::string>& inputs, const std::vector<std::string>& outputs);

// Memory this process may use: physical memory, lowered to the cgroup limit
// and to RLIMIT_AS / RLIMIT_DATA when set.
std::uint64_t usable_memory_bytes();
// True if `voxels` x `bytes_per_voxel` bytes fit in 75 % of
// usable_memory_bytes() (a quarter left for the OS and the device runtime).
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
// "<path>: cannot open: <strerror>" (a directory reads as EISDIR) or
// "<path>: not a regular file (a FIFO)" for FIFOs, devices and sockets,
// which are refused without blocking.
FilePtr open_for_reading(const std::string& path);
// The kind of a non-regular file for messages ("a FIFO", "a character
// device", ...); empty for a regular file.
std::string special_file_kind(unsigned mode);

// The path of a detached data file named `name` in the header `header`,
// resolved against the header's directory, under the data-file policy:
// not "-" (standard input), inside the header's directory tree (after
// following links) unless SOFTSHELL_DATA_FILES=any, an existing regular
// file. Throws InputError "<header>: data file <name>: <problem>".
std::string resolve_data_file(const std::string& header, const std::string& name);
// Size in bytes of an open file.
std::uint64_t file_size(std::FILE* f);
// Reads up to `n` bytes; returns how many were read (fewer only at EOF).
// Throws InputError naming `path` on a read error.
std::size_t read_up_to(std::FILE* f, void* data, std::size_t n, const std::string& path);

// A temporary file ".<name>.tmp-XXXXXX" in the directory of `target`,
// renamed onto `target` by commit(); removed by the destructor if commit()
// was not reached, so a failed write leaves nothing behind. More:
//  - the target, when it exists, must be a regular file (never replace a
//    device such as /dev/full, a FIFO or a directory);
//  - SIGINT, SIGTERM and SIGHUP (unless ignored) remove every temporary
//    file still open, then take their previous action (the default: the
//    process dies of the signal; or a library's handler, such as LLVM's);
//  - the writer holds an flock() on its temporary file, and the constructor
//    removes stale temporaries of the same target: our own name pattern,
//    older than kStaleTempSeconds, and unlocked (their writer is gone: a
//    SIGKILL, a power cut);
//  - commit_together() publishes several files (a .mhd header and its data)
//    under a lock on their directory, so concurrent writers of the same
//    output never leave a header of one run beside the data of another.
class AtomicFile {
 public:
  static constexpr long kStaleTempSeconds = 600;

  explicit AtomicFile(std::string target);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  std::FILE* file() const { return file_.get(); }
  const std::string& target() const { return target_; }
  const std::string& temp_path() const { return temp_; }
  // Writes all of `data`; throws InputError on a short write (e.g. ENOSPC).
  void write(const void* data, std::size_t n);
  // Flushes, syncs and closes the file, checking each step (where a full
  // disk shows), then renames it onto the target.
  void commit();
  // finish() then, under one lock of the directory, the renames, in order:
  // all files are complete before any replaces its target.
  static void commit_together(const std::vector<AtomicFile*>& files);

 private:
  void finish();   // flush, fsync, close
  void publish();  // rename onto the target
  std::string target_, temp_;
  FilePtr file_;
  int slot_ = -1;  // in the signal handler's list of temporaries
  bool committed_ = false;
};

// Installs AtomicFile's signal handling (once; AtomicFile calls it too).
// Call it first thing in main(): what it keeps is the signal dispositions
// it finds, and libraries installed later (LLVM inside PoCL) replace an
// ignored SIGINT with a handler of their own.
void install_signal_cleanup();

// Removes stale temporaries of `target` (see AtomicFile); returns how many.
// `max_age_seconds` < 0: AtomicFile::kStaleTempSeconds.
std::size_t remove_stale_temporaries(const std::string& target, long max_age_seconds = -1);

// PLUS tracked-frame sequences (.igs.mha, .igs.nrrd: 2-D frames stacked
// along the third axis, each with its own pose) carry per-frame header keys
// "Seq_FrameNNNN_<name>". True for a key that marks a sequence: one of a
// frame after the first, or a per-frame transform. (PLUS's reconstructed
// volumes keep a lone "Seq_Frame0000_ImageStatus", which is not one.)
bool is_tracked_frame_key(const std::string& key);
// The one-line refusal for such a file (InputError naming `path`).
InputError tracked_frame_error(const std::string& path, const std::string& key);

Volume read_nrrd(const std::string& path, std::optional<std::size_t> frame = std::nullopt);
// any_frame: a sequence's header without a frame chosen (for `info`).
VolumeHeader read_nrrd_header(const std::string& path, std::optional<std::size_t> frame = std::nullopt,
                              bool any_frame = false);
void write_nrrd(const std::string& path, const Volume& v, const WriteOptions& opt);
// Every frame of a NRRD (one for a 3-D file); `frames` of one geometry as a
// 4-D NRRD (frame axis kind list, label "frame"; one frame: a 3-D file).
std::vector<Volume> read_nrrd_frames(const std::string& path);
void write_nrrd_frames(const std::string& path, const std::vector<const Volume*>& frames, const WriteOptions& opt);
Volume read_metaimage(const std::string& path);
// NIfTI (host/io_nifti.cpp; only when nifti_supported()).
Volume read_nifti(const std::string& path);
VolumeHeader read_nifti_header(const std::string& path);
// The whole of `in` deflated: a zlib stream (as MetaIO, ITK, VTK and PLUS
// write MetaImage data), or with `gzip` one gzip member (.nii.gz).
std::vector<unsigned char> deflate_all(const std::string& path, const std::vector<unsigned char>& in, bool gzip = false);
// `gzipped`: .nii.gz. NIfTI-1, sform and qform in RAS (host/io_nifti.cpp).
void write_nifti(const std::string& path, const Volume& v, const WriteOptions& opt, bool gzipped);
// DICOM (host/io_dicom.cpp, through GDCM): a multi-frame 3-D file, a folder
// holding one series of slices, or Philips' Cartesian 3D+t file (frames as
// a sequence: `frame` as for NRRD). Chosen for a folder, a file with "DICM"
// at byte 128, or a .dcm / .dicom name.
Volume read_dicom(const std::string& path, std::optional<std::size_t> frame);
VolumeHeader read_dicom_header(const std::string& path, std::optional<std::size_t> frame, bool any_frame);
// GE Kretz .vol (host/io_kretz.cpp): scan-converted to a Cartesian grid.
Volume read_kretz(const std::string& path);
VolumeHeader read_kretz_header(const std::string& path);
// VTK XML ImageData (host/io_vti.cpp).
Volume read_vti(const std::string& path);
// Raw appended samples (zlib blocks when opt.compress), LPS world.
void write_vti(const std::string& path, const Volume& v, const WriteOptions& opt);
VolumeHeader read_vti_header(const std::string& path);
VolumeHeader read_metaimage_header(const std::string& path);
// `detached`: .mhd header plus "<stem>.raw" (".zraw" when compressed).
void write_metaimage(const std::string& path, const Volume& v, const WriteOptions& opt,
                     bool detached);

}  // namespace io_detail
}  // namespace softshell
