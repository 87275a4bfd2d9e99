// DICOM 3-D volumes through GDCM (Debian libgdcm-dev; docs/formats.md,
// "DICOM"). Three layouts are read:
//  - one multi-frame file whose frames are the slices of a volume (Enhanced
//    US Volume, Enhanced CT/MR, multi-frame secondary capture, ...);
//  - a folder of single-frame slices of one series, ordered by their
//    position along the slice normal;
//  - the Cartesian 3D+t file Philips QLAB exports (SOP class
//    1.2.840.113543.6.6.1.3.10002): 8-bit frames of slices x rows x columns
//    at the end of the file, the slice count in (3001,1001), the slice
//    spacing in (3001,1003) and the in-plane spacing in Physical Delta X/Y,
//    all in cm (the layout SlicerHeart's importer reads).
// 2-D ultrasound (single images and cine loops over time) is refused with a
// message saying what it is. GDCM's own messages are switched off: every
// failure is one line of ours.
#include <gdcmAttribute.h>
#include <gdcmDataSet.h>
#include <gdcmImage.h>
#include <gdcmImageHelper.h>
#include <gdcmImageReader.h>
#include <gdcmReader.h>
#include <gdcmSequenceOfItems.h>
#include <gdcmTrace.h>

#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <new>
#include <cstdio>
#include <stdexcept>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "error.hpp"
#include "io.hpp"
#include "text.hpp"

namespace fs = std::filesystem;

namespace softshell::io_detail {
namespace {

constexpr const char* kPhilipsCartesian = "1.2.840.113543.6.6.1.3.10002";
constexpr const char* kEnhancedUsVolume = "1.2.840.10008.5.1.4.1.1.6.2";
// 2-D ultrasound: image and multi-frame (cine) storage, current and retired.
const std::set<std::string> kUltrasound2d{"1.2.840.10008.5.1.4.1.1.6.1", "1.2.840.10008.5.1.4.1.1.6",
                                          "1.2.840.10008.5.1.4.1.1.3.1", "1.2.840.10008.5.1.4.1.1.3"};
const gdcm::Tag kPixelData(0x7fe0, 0x0010);

// GDCM is not thread-safe in its global trace settings; reads are serialised.
std::mutex& gdcm_mutex() {
  static std::mutex m;
  return m;
}

void quiet_gdcm() {
  static std::once_flag once;
  std::call_once(once, [] {
    gdcm::Trace::SetDebug(false);
    gdcm::Trace::SetWarning(false);
    gdcm::Trace::SetError(false);
  });
}

std::string trimmed(std::string s) {
  while (!s.empty() && (s.back() == '\0' || s.back() == ' ')) s.pop_back();
  std::size_t b = 0;
  while (b < s.size() && s[b] == ' ') ++b;
  return s.substr(b);
}

const gdcm::DataElement* element(const gdcm::DataSet& ds, gdcm::Tag t) {
  if (!ds.FindDataElement(t)) return nullptr;
  const gdcm::DataElement& de = ds.GetDataElement(t);
  return de.IsEmpty() ? nullptr : &de;
}

std::string text_of(const gdcm::DataSet& ds, gdcm::Tag t) {
  const gdcm::DataElement* de = element(ds, t);
  const gdcm::ByteValue* bv = de ? de->GetByteValue() : nullptr;
  if (!bv) return "";
  return trimmed(std::string(bv->GetPointer(), bv->GetLength()));
}

// The numbers of an element: text VRs (DS, IS) split at '\'; binary VRs
// little-endian by their VR; an implicit-VR element (private tags) as
// float32 (4 bytes) or float64 (8 bytes) when `real`, else as unsigned
// 16/32-bit integers.
std::vector<double> numbers_of(const gdcm::DataElement* de, bool real) {
  std::vector<double> out;
  const gdcm::ByteValue* bv = de ? de->GetByteValue() : nullptr;
  if (!bv) return out;
  const char* p = bv->GetPointer();
  const std::size_t n = bv->GetLength();
  const gdcm::VR vr = de->GetVR();
  const auto binary = [&](std::size_t size, auto decode) {
    for (std::size_t i = 0; i + size <= n && out.size() < 64; i += size) out.push_back(decode(p + i));
  };
  const auto u16 = [](const char* b) { std::uint16_t v; std::memcpy(&v, b, 2); return double(v); };
  const auto s16 = [](const char* b) { std::int16_t v; std::memcpy(&v, b, 2); return double(v); };
  const auto u32 = [](const char* b) { std::uint32_t v; std::memcpy(&v, b, 4); return double(v); };
  const auto s32 = [](const char* b) { std::int32_t v; std::memcpy(&v, b, 4); return double(v); };
  const auto f32 = [](const char* b) { float v; std::memcpy(&v, b, 4); return double(v); };
  const auto f64 = [](const char* b) { double v; std::memcpy(&v, b, 8); return v; };
  if (vr == gdcm::VR::DS || vr == gdcm::VR::IS || vr == gdcm::VR::LO || vr == gdcm::VR::SH) {
    std::string s(p, n);
    std::stringstream ss(s);
    std::string item;
    while (std::getline(ss, item, '\\') && out.size() < 64) {
      item = trimmed(item);
      char* end = nullptr;
      const double v = std::strtod(item.c_str(), &end);
      if (item.empty() || *end != '\0') return {};
      out.push_back(v);
    }
  } else if (vr == gdcm::VR::US) {
    binary(2, u16);
  } else if (vr == gdcm::VR::SS) {
    binary(2, s16);
  } else if (vr == gdcm::VR::UL) {
    binary(4, u32);
  } else if (vr == gdcm::VR::SL) {
    binary(4, s32);
  } else if (vr == gdcm::VR::FL) {
    binary(4, f32);
  } else if (vr == gdcm::VR::FD) {
    binary(8, f64);
  } else if (n == 8) {
    binary(8, real ? f64 : [](const char* b) { std::uint64_t v; std::memcpy(&v, b, 8); return double(v); });
  } else if (n == 4) {
    binary(4, real ? f32 : u32);
  } else if (n == 2 && !real) {
    binary(2, u16);
  }
  return out;
}

// The first item's data set of a sequence element, or null.
const gdcm::DataSet* first_item(const gdcm::DataSet& ds, gdcm::Tag seq, std::size_t index = 1) {
  const gdcm::DataElement* de = element(ds, seq);
  if (!de) return nullptr;
  gdcm::SmartPointer<gdcm::SequenceOfItems> sq = de->GetValueAsSQ();
  if (!sq || sq->GetNumberOfItems() < index) return nullptr;
  return &sq->GetItem(index).GetNestedDataSet();
}

// A value of an enhanced multi-frame file's functional groups: the shared
// group first, else the first frame's.
const gdcm::DataElement* functional(const gdcm::DataSet& ds, gdcm::Tag macro, gdcm::Tag value, std::size_t frame = 1) {
  const gdcm::Tag shared(0x5200, 0x9229), per_frame(0x5200, 0x9230);
  for (const gdcm::Tag& groups : {shared, per_frame}) {
    if (frame != 1 && groups == shared) continue;  // another frame's own value
    const gdcm::DataSet* g = first_item(ds, groups, groups == per_frame ? frame : 1);
    const gdcm::DataSet* m = g ? first_item(*g, macro) : nullptr;
    if (m) {
      if (const gdcm::DataElement* de = element(*m, value)) return de;
    }
  }
  return nullptr;
}

// What a DICOM input holds, from its header(s) alone.
struct DicomLayout {
  enum class Kind { MultiFrame, Series, Philips } kind = Kind::MultiFrame;
  Dims3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1}, origin{0, 0, 0};
  Mat3 axes = kIdentityAxes;
  bool patient_space = false;  // origin and axes in DICOM's patient coordinates (LPS)
  ScalarType type = ScalarType::UInt8;
  std::size_t frames = 1;      // Philips: time frames
  std::uint64_t data_offset = 0;  // Philips: where frame 0's samples start
  std::vector<std::string> files;  // multi-frame/Philips: the file; series: the slices in order
};

std::optional<ScalarType> scalar_type_of(const gdcm::PixelFormat& pf) {
  switch (pf.GetScalarType()) {
    case gdcm::PixelFormat::UINT8: return ScalarType::UInt8;
    case gdcm::PixelFormat::INT8: return ScalarType::Int8;
    case gdcm::PixelFormat::UINT16: return ScalarType::UInt16;
    case gdcm::PixelFormat::INT16: return ScalarType::Int16;
    case gdcm::PixelFormat::UINT32: return ScalarType::UInt32;
    case gdcm::PixelFormat::INT32: return ScalarType::Int32;
    case gdcm::PixelFormat::FLOAT32: return ScalarType::Float32;
    case gdcm::PixelFormat::FLOAT64: return ScalarType::Float64;
    default: return std::nullopt;
  }
}

Vec3d cross(const Vec3d& a, const Vec3d& b) {
  return {a[1] * b[2] - a[2] * b[1] + 0.0, a[2] * b[0] - a[0] * b[2] + 0.0, a[0] * b[1] - a[1] * b[0] + 0.0};
}
double dot(const Vec3d& a, const Vec3d& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Row and column directions (DICOM's Image Orientation): unit, orthogonal.
bool orientation_ok(const std::vector<double>& c) {
  if (c.size() != 6) return false;
  const Vec3d r{c[0], c[1], c[2]}, k{c[3], c[4], c[5]};
  return std::fabs(dot(r, r) - 1) < 1e-3 && std::fabs(dot(k, k) - 1) < 1e-3 && std::fabs(dot(r, k)) < 1e-3;
}

// The grid's place from a data set (our own reading, the same for every SOP
// class): Image Position / Orientation (Patient) and Pixel Spacing at the
// top level or in the functional groups (Plane Position, Plane
// Orientation, Pixel Measures); for Enhanced US Volume the (Volume)
// attributes. The slice step: from the first two frames' positions along
// the normal when the file gives them (its sign decides the third axis),
// else Spacing Between Slices, else Slice Thickness, else 1 mm.
struct PlaneGeometry {
  Vec3d spacing{1, 1, 1}, origin{0, 0, 0};
  Mat3 axes = kIdentityAxes;
  bool positioned = false;  // position and orientation given
};

PlaneGeometry plane_geometry(const gdcm::DataSet& ds, bool volume_frame) {
  const gdcm::Tag pos_macro = volume_frame ? gdcm::Tag(0x0020, 0x930e) : gdcm::Tag(0x0020, 0x9113);
  const gdcm::Tag pos_tag = volume_frame ? gdcm::Tag(0x0020, 0x9301) : gdcm::Tag(0x0020, 0x0032);
  const gdcm::Tag ori_macro = volume_frame ? gdcm::Tag(0x0020, 0x930f) : gdcm::Tag(0x0020, 0x9116);
  const gdcm::Tag ori_tag = volume_frame ? gdcm::Tag(0x0020, 0x9302) : gdcm::Tag(0x0020, 0x0037);
  const gdcm::Tag measures(0x0028, 0x9110);
  const auto value = [&](gdcm::Tag macro, gdcm::Tag tag, std::size_t frame = 1) {
    const gdcm::DataElement* de = frame == 1 ? element(ds, tag) : nullptr;
    if (!de) de = functional(ds, macro, tag, frame);
    return numbers_of(de, true);
  };
  PlaneGeometry g;
  const std::vector<double> pos = value(pos_macro, pos_tag), ori = value(ori_macro, ori_tag);
  const std::vector<double> pixel = value(measures, gdcm::Tag(0x0028, 0x0030));
  if (pixel.size() == 2 && pixel[0] > 0 && pixel[1] > 0) g.spacing = {pixel[1], pixel[0], 1};  // (rows, columns) apart
  std::vector<double> between = value(measures, gdcm::Tag(0x0018, 0x0088));
  if (between.empty()) between = value(measures, gdcm::Tag(0x0018, 0x0050));
  if (!between.empty() && std::isfinite(between[0]) && between[0] != 0) g.spacing[2] = std::fabs(between[0]);
  Vec3d n = kIdentityAxes[2];
  if (orientation_ok(ori)) {
    g.axes[0] = {ori[0], ori[1], ori[2]};
    g.axes[1] = {ori[3], ori[4], ori[5]};
    n = cross(g.axes[0], g.axes[1]);
    g.axes[2] = n;
  }
  if (pos.size() == 3) g.origin = {pos[0], pos[1], pos[2]};
  g.positioned = pos.size() == 3 && orientation_ok(ori);
  const std::vector<double> pos2 = numbers_of(functional(ds, pos_macro, pos_tag, 2), true);
  if (pos.size() == 3 && pos2.size() == 3) {
    const double step = dot({pos2[0] - pos[0], pos2[1] - pos[1], pos2[2] - pos[2]}, n);
    if (std::isfinite(step) && std::fabs(step) > 1e-9) {
      g.spacing[2] = std::fabs(step);
      if (step < 0) g.axes[2] = {-n[0] + 0.0, -n[1] + 0.0, -n[2] + 0.0};  // frames against the normal
    }
  }
  return g;
}

// Native (uncompressed) pixel data must be whole in the file: GDCM pads a
// truncated one silently. The Pixel Data element is found as the first
// (7FE0,0010) tag in the file's bytes (an earlier chance match inside
// another value only weakens the check, it never refuses a whole file).
void check_native_pixel_data(const std::string& path, const gdcm::File& f, std::uint64_t pixels) {
  if (f.GetHeader().GetDataSetTransferSyntax().IsEncapsulated()) return;  // the decoder checks its stream
  const std::uint64_t bytes = pixels * gdcm::ImageHelper::GetPixelFormatValue(f).GetPixelSize();
  const std::uint64_t size = fs::file_size(path);
  io_detail::FilePtr in = io_detail::open_for_reading(path);
  static const char tag[4] = {'\xe0', '\x7f', '\x10', '\x00'};
  std::vector<char> buf(1 << 16);
  std::uint64_t base = 0;
  std::size_t keep = 0;
  for (;;) {
    const std::size_t got = std::fread(buf.data() + keep, 1, buf.size() - keep, in.get());
    const std::size_t n = keep + got;
    for (std::size_t i = 0; i + 6 <= n; ++i) {
      if (std::memcmp(buf.data() + i, tag, 4) != 0) continue;
      const bool explicit_vr = (buf[i + 4] == 'O' && (buf[i + 5] == 'B' || buf[i + 5] == 'W')) ||
                               (buf[i + 4] == 'U' && buf[i + 5] == 'N');
      const std::uint64_t value = base + i + (explicit_vr ? 12 : 8);
      if (value + bytes > size)
        throw input_error(path, "DICOM: the pixel data is cut short (" + std::to_string(bytes) +
                                    " bytes of samples declared, " + std::to_string(size > value ? size - value : 0) +
                                    " in the file)");
      return;
    }
    if (got == 0) return;  // no Pixel Data tag found: GDCM's own reading decides
    keep = std::min<std::size_t>(n, 5);
    std::memmove(buf.data(), buf.data() + n - keep, keep);
    base += n - keep;
  }
}

// Reads a file's header (every element before the pixel data).
bool read_header(const std::string& file, gdcm::Reader& reader) {
  reader.SetFileName(file.c_str());
  std::set<gdcm::Tag> skip;
  return reader.ReadUpToTag(kPixelData, skip);
}

std::string sop_class_of(const gdcm::File& f) {
  std::string sop = text_of(f.GetDataSet(), gdcm::Tag(0x0008, 0x0016));
  if (sop.empty()) sop = trimmed(f.GetHeader().GetMediaStorageAsString());
  return sop;
}

void check_extent(const std::string& path, const Dims3& dims, const Vec3d& spacing, ScalarType type) {
  checked_voxels(path, dims, type);
  check_geometry(path, spacing, {0, 0, 0});
}

DicomLayout philips_layout(const std::string& path, const gdcm::DataSet& ds) {
  DicomLayout l;
  l.kind = DicomLayout::Kind::Philips;
  l.files = {path};
  const auto count = [&](gdcm::Tag t, const char* what) {
    const std::vector<double> v = numbers_of(element(ds, t), false);
    if (v.empty() || !(v[0] >= 1 && v[0] <= 65535) || v[0] != std::floor(v[0]))
      throw input_error(path, std::string("Philips Cartesian DICOM: no valid ") + what);
    return std::size_t(v[0]);
  };
  const std::size_t cols = count(gdcm::Tag(0x0028, 0x0011), "Columns (0028,0011)");
  const std::size_t rows = count(gdcm::Tag(0x0028, 0x0010), "Rows (0028,0010)");
  const std::size_t slices = count(gdcm::Tag(0x3001, 0x1001), "slice count (3001,1001)");
  std::vector<double> frames = numbers_of(element(ds, gdcm::Tag(0x0028, 0x0008)), false);
  l.frames = frames.empty() ? 1 : std::size_t(std::max(1.0, frames[0]));
  if (frames.size() == 1 && !(frames[0] >= 1 && frames[0] <= 1e6))
    throw input_error(path, "Philips Cartesian DICOM: Number of Frames (0028,0008) is not a count");
  const std::vector<double> bits = numbers_of(element(ds, gdcm::Tag(0x0028, 0x0100)), false);
  if (!bits.empty() && bits[0] != 8)
    throw input_error(path, "Philips Cartesian DICOM: " + std::to_string(int(bits[0])) +
                                " bits allocated; only 8-bit samples are known in this layout");
  const auto delta = [&](gdcm::Tag t, const char* what) {
    const gdcm::DataElement* de = element(ds, t);
    if (!de)
      if (const gdcm::DataSet* region = first_item(ds, gdcm::Tag(0x0018, 0x6011))) de = element(*region, t);
    const std::vector<double> v = numbers_of(de, true);
    if (v.empty() || !std::isfinite(v[0]) || !(v[0] > 0))
      throw input_error(path, std::string("Philips Cartesian DICOM: no valid ") + what);
    return v[0] * 10.0;  // cm -> mm
  };
  l.spacing = {delta(gdcm::Tag(0x0018, 0x602c), "Physical Delta X (0018,602C)"),
               delta(gdcm::Tag(0x0018, 0x602e), "Physical Delta Y (0018,602E)"),
               delta(gdcm::Tag(0x3001, 0x1003), "slice spacing (3001,1003)")};
  l.dims = {cols, rows, slices};
  l.type = ScalarType::UInt8;
  check_extent(path, l.dims, l.spacing, l.type);
  const std::uint64_t frame_bytes = std::uint64_t(cols) * rows * slices;
  std::uint64_t all = 0;
  if (__builtin_mul_overflow(frame_bytes, std::uint64_t(l.frames), &all))
    throw input_error(path, "Philips Cartesian DICOM: the declared frames overflow the file size");
  const std::uint64_t size = fs::file_size(path);
  if (all + 132 > size)
    throw input_error(path, "Philips Cartesian DICOM: " + std::to_string(l.frames) + " frames of " +
                                dims_text(l.dims) + " need " + std::to_string(all) + " bytes of samples, the file has " +
                                std::to_string(size));
  l.data_offset = size - all;  // the samples end the file
  return l;
}

DicomLayout multiframe_layout(const std::string& path, const gdcm::File& f) {
  const gdcm::DataSet& ds = f.GetDataSet();
  const std::string sop = sop_class_of(f);
  DicomLayout l;
  l.files = {path};
  const std::vector<unsigned int> d = gdcm::ImageHelper::GetDimensionsValue(f);
  if (d.size() < 3 || d[0] == 0 || d[1] == 0) throw input_error(path, "DICOM: no image (Rows, Columns) in this file");
  if (kUltrasound2d.count(sop))
    throw input_error(path, "2-D ultrasound DICOM (" + std::string(d[2] > 1 ? "a cine loop of " + std::to_string(d[2]) +
                                                                                 " frames over time"
                                                                           : "one image") +
                                "), not a 3-D volume; export the volume from the scanner's software as Enhanced US "
                                "Volume DICOM, Philips Cartesian DICOM, Kretz .vol or NRRD");
  if (d[2] < 2)
    throw input_error(path, "one 2-D DICOM slice: give the folder that holds the whole series");
  l.dims = {d[0], d[1], d[2]};
  const gdcm::PixelFormat pf = gdcm::ImageHelper::GetPixelFormatValue(f);
  const auto type = scalar_type_of(pf);
  if (!type) throw input_error(path, std::string("DICOM: unsupported sample type ") + pf.GetScalarTypeAsString());
  l.type = *type;
  const PlaneGeometry g = plane_geometry(ds, sop == kEnhancedUsVolume);
  l.spacing = g.spacing;
  l.origin = g.origin;
  l.axes = g.axes;
  l.patient_space = sop != kEnhancedUsVolume;
  for (int a = 0; a < 3; ++a)
    if (!std::isfinite(l.origin[a])) throw input_error(path, "DICOM: the image position is not finite");
  check_extent(path, l.dims, l.spacing, l.type);
  check_geometry(path, l.spacing, l.origin);
  return l;
}

DicomLayout series_layout(const std::string& dir) {
  struct Slice {
    std::string file;
    double position = 0;
    Vec3d ipp{0, 0, 0};
  };
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    if (names.size() > 100000) throw input_error(dir, "DICOM series: more than 100000 files");
    std::error_code e2;
    if (it->is_regular_file(e2) && it->path().filename().string()[0] != '.') names.push_back(it->path().string());
  }
  if (ec) throw input_error(dir, "cannot list the folder: " + ec.message());
  std::sort(names.begin(), names.end());
  DicomLayout l;
  l.kind = DicomLayout::Kind::Series;
  l.patient_space = true;
  std::vector<Slice> slices;
  std::set<std::string> series;
  std::vector<double> orient;
  Dims3 dims{0, 0, 0};
  Vec3d spacing{1, 1, 1};
  std::optional<ScalarType> type;
  for (const std::string& name : names) {
    gdcm::Reader r;
    if (!read_header(name, r)) continue;  // not DICOM (a README, a thumbnail): skipped
    const gdcm::File& f = r.GetFile();
    const gdcm::DataSet& ds = f.GetDataSet();
    if (!element(ds, gdcm::Tag(0x0028, 0x0010))) continue;  // no image (DICOMDIR, a report)
    const std::string uid = text_of(ds, gdcm::Tag(0x0020, 0x000e));
    series.insert(uid);
    if (series.size() > 1)
      throw input_error(dir, "DICOM: more than one series in this folder (" + *series.begin() + ", " +
                                 *series.rbegin() + "): give a folder that holds one series");
    const std::vector<unsigned int> d = gdcm::ImageHelper::GetDimensionsValue(f);
    if (d.size() < 3 || d[0] == 0 || d[1] == 0) throw input_error(name, "DICOM: no image (Rows, Columns)");
    if (d[2] > 1)
      throw input_error(name, "DICOM: a multi-frame file (" + std::to_string(d[2]) +
                                  " frames) in a series folder: give the file itself");
    const auto t = scalar_type_of(gdcm::ImageHelper::GetPixelFormatValue(f));
    if (!t) throw input_error(name, "DICOM: unsupported sample type");
    const PlaneGeometry g = plane_geometry(ds, false);
    if (!g.positioned)
      throw input_error(name, "DICOM: no valid Image Position / Orientation (Patient): a series needs both to be stacked");
    const std::vector<double> c{g.axes[0][0], g.axes[0][1], g.axes[0][2], g.axes[1][0], g.axes[1][1], g.axes[1][2]};
    const Vec3d o = g.origin;
    const Vec3d sp = g.spacing;
    if (slices.empty()) {
      dims = {d[0], d[1], 0};
      orient = c;
      type = t;
      spacing = {sp[0], sp[1], 1};
    } else {
      if (dims[0] != d[0] || dims[1] != d[1])
        throw input_error(name, "DICOM: " + std::to_string(d[0]) + "x" + std::to_string(d[1]) + " pixels, unlike " +
                                    slices.front().file + " (" + std::to_string(dims[0]) + "x" +
                                    std::to_string(dims[1]) + "): the slices of a volume share one size");
      for (int i = 0; i < 6; ++i)
        if (std::fabs(c[i] - orient[i]) > 1e-4)
          throw input_error(name, "DICOM: its orientation differs from " + slices.front().file + "'s (a localiser?)");
      if (*t != *type) throw input_error(name, "DICOM: its sample type differs from " + slices.front().file + "'s");
    }
    check_native_pixel_data(name, f, std::uint64_t(d[0]) * d[1]);
    slices.push_back({name, 0, {o[0], o[1], o[2]}});
  }
  if (slices.size() < 2)
    throw input_error(dir, slices.empty() ? "a folder with no DICOM image in it (expected a volume file, or a folder "
                                            "holding one DICOM series)"
                                          : "one DICOM slice in this folder: a volume needs at least two");
  const Vec3d row{orient[0], orient[1], orient[2]}, col{orient[3], orient[4], orient[5]};
  const Vec3d n = cross(row, col);
  for (Slice& s : slices) s.position = dot(s.ipp, n);
  std::sort(slices.begin(), slices.end(), [](const Slice& a, const Slice& b) { return a.position < b.position; });
  std::vector<double> steps;
  for (std::size_t i = 1; i < slices.size(); ++i) steps.push_back(slices[i].position - slices[i - 1].position);
  std::vector<double> sorted = steps;
  std::sort(sorted.begin(), sorted.end());
  const double step = sorted[sorted.size() / 2];
  if (!(sorted.front() > 1e-6 * std::max(1.0, std::fabs(step))))
    throw input_error(dir, "DICOM: two slices at the same position along the slice normal (two series, or a repeat?)");
  if (sorted.back() - sorted.front() > 0.01 * step) {
    std::ostringstream m;
    m << "DICOM: the slices are unevenly spaced (" << sorted.front() << " to " << sorted.back()
      << " mm apart): a missing slice?";
    throw input_error(dir, m.str());
  }
  l.dims = {dims[0], dims[1], slices.size()};
  l.spacing = {spacing[0], spacing[1], step};
  l.type = *type;
  l.origin = slices.front().ipp;
  l.axes = {row, col, n};
  for (const Slice& s : slices) l.files.push_back(s.file);
  check_extent(dir, l.dims, l.spacing, l.type);
  check_geometry(dir, l.spacing, l.origin);
  return l;
}

DicomLayout layout_of(const std::string& path) {
  quiet_gdcm();
  std::error_code ec;
  if (fs::is_directory(path, ec)) return series_layout(path);
  gdcm::Reader r;
  if (!read_header(path, r)) throw input_error(path, "not a DICOM file GDCM can parse");
  const gdcm::File& f = r.GetFile();
  if (sop_class_of(f) == kPhilipsCartesian) return philips_layout(path, f.GetDataSet());
  if (!element(f.GetDataSet(), gdcm::Tag(0x0028, 0x0010)))
    throw input_error(path, "a DICOM file without an image (a DICOMDIR, a report, ...)");
  DicomLayout l = multiframe_layout(path, f);
  check_native_pixel_data(path, f, std::uint64_t(l.dims[0]) * l.dims[1] * l.dims[2]);
  return l;
}

VolumeHeader header_of(const DicomLayout& l) {
  VolumeHeader h;
  h.dims = l.dims;
  h.type = l.type;
  h.spacing = l.spacing;
  h.origin = l.origin;
  h.frame.axes = l.axes;
  if (l.patient_space) h.frame.space = "left-posterior-superior";
  h.files = l.files;
  h.frames = l.frames;
  return h;
}

void check_frame(const std::string& path, const DicomLayout& l, std::optional<std::size_t> frame, bool any_frame) {
  if (frame && *frame >= l.frames)
    throw input_error(path, "--frame " + std::to_string(*frame) + ": the file holds " + std::to_string(l.frames) +
                                (l.frames == 1 ? " frame (0)" : " frames (0 to " + std::to_string(l.frames - 1) + ")"));
  if (!frame && l.frames > 1 && !any_frame)
    throw input_error(path, "a sequence of " + std::to_string(l.frames) + " 3-D frames of " + dims_text(l.dims) +
                                ": choose one with --frame K (0 to " + std::to_string(l.frames - 1) + ")");
}

// One decoded image's samples (the whole multi-frame file, or one slice)
// into `out`, as grey values in the file's units.
void decode_image(const std::string& file, const gdcm::Image& img, std::size_t pixels, float* out, bool* rescaled) {
  const gdcm::PixelFormat pf = img.GetPixelFormat();
  const auto type = scalar_type_of(pf);
  if (!type) throw input_error(file, std::string("DICOM: unsupported sample type ") + pf.GetScalarTypeAsString());
  const unsigned spp = pf.GetSamplesPerPixel();
  const gdcm::PhotometricInterpretation pi = img.GetPhotometricInterpretation();
  const bool mono = pi == gdcm::PhotometricInterpretation::MONOCHROME1 || pi == gdcm::PhotometricInterpretation::MONOCHROME2;
  const bool rgb = pi == gdcm::PhotometricInterpretation::RGB;
  const bool ybr = pi == gdcm::PhotometricInterpretation::YBR_FULL || pi == gdcm::PhotometricInterpretation::YBR_FULL_422;
  if (!((mono && spp == 1) || ((rgb || ybr) && spp == 3)))
    throw input_error(file, std::string("DICOM: photometric interpretation ") + pi.GetString() + " with " +
                                std::to_string(spp) + " samples per pixel is not read (grey or RGB/YBR colour only)");
  const std::size_t size = scalar_type_size(*type);
  const std::size_t expected = pixels * spp * size;
  if (img.GetBufferLength() != expected)
    throw input_error(file, "DICOM: the pixel data holds " + std::to_string(img.GetBufferLength()) + " bytes, " +
                                std::to_string(expected) + " expected");
  std::vector<char> buf(expected);
  if (!img.GetBuffer(buf.data())) throw input_error(file, "DICOM: the pixel data cannot be decoded");
  const auto sample = [&](std::size_t i) -> double {
    const char* p = buf.data() + i * size;
    switch (*type) {
      case ScalarType::UInt8: return double(static_cast<unsigned char>(*p));
      case ScalarType::Int8: return double(static_cast<signed char>(*p));
      case ScalarType::UInt16: { std::uint16_t v; std::memcpy(&v, p, 2); return v; }
      case ScalarType::Int16: { std::int16_t v; std::memcpy(&v, p, 2); return v; }
      case ScalarType::UInt32: { std::uint32_t v; std::memcpy(&v, p, 4); return v; }
      case ScalarType::Int32: { std::int32_t v; std::memcpy(&v, p, 4); return v; }
      case ScalarType::Float32: { float v; std::memcpy(&v, p, 4); return v; }
      case ScalarType::Float64: { double v; std::memcpy(&v, p, 8); return v; }
      default: return 0.0;
    }
  };
  const bool planar = spp == 3 && img.GetPlanarConfiguration() == 1;
  const std::size_t frame_pixels = std::size_t(img.GetDimension(0)) * img.GetDimension(1);
  const double slope = img.GetSlope(), intercept = img.GetIntercept();
  const bool rescale = mono && (slope != 1.0 || intercept != 0.0) && std::isfinite(slope) && std::isfinite(intercept);
  if (rescaled) *rescaled = rescale;
  // MONOCHROME1 (white is low) is mirrored within the stored range, so the
  // samples stay the stored type's: top - v with top = 2^bits - 1 unsigned,
  // -1 for a signed type ([-2^(bits-1), 2^(bits-1) - 1] onto itself; 2^bits
  // - 1 there gave 128..383 for int8, which no int8 file holds: found by
  // fuzz_dicom, tests/data/repro/dicom_signed_monochrome1.dcm).
  const bool is_signed = *type == ScalarType::Int8 || *type == ScalarType::Int16 || *type == ScalarType::Int32;
  const double top = pi == gdcm::PhotometricInterpretation::MONOCHROME1 && scalar_type_is_integer(*type)
                         ? (is_signed ? -1.0 : std::ldexp(1.0, int(pf.GetBitsStored())) - 1.0)
                         : 0.0;
  for (std::size_t i = 0; i < pixels; ++i) {
    double v;
    if (spp == 1) {
      v = sample(i);
      if (pi == gdcm::PhotometricInterpretation::MONOCHROME1) v = top - v;  // white is low
      if (rescale) v = v * slope + intercept;
    } else {
      std::size_t at[3];
      if (planar) {
        const std::size_t fr = i / frame_pixels, j = i % frame_pixels;
        for (int c = 0; c < 3; ++c) at[c] = fr * frame_pixels * 3 + c * frame_pixels + j;
      } else {
        for (int c = 0; c < 3; ++c) at[c] = i * 3 + c;
      }
      // Grey from colour: Rec. 601 luma (RGB), or Y itself (YBR).
      v = ybr ? sample(at[0]) : 0.299 * sample(at[0]) + 0.587 * sample(at[1]) + 0.114 * sample(at[2]);
    }
    out[i] = float(v);
  }
}

Volume read_layout(const std::string& path, const DicomLayout& l, std::optional<std::size_t> frame) {
  Volume v(l.dims, l.spacing, l.type);
  v.origin = l.origin;
  v.frame.axes = l.axes;
  if (l.patient_space) v.frame.space = "left-posterior-superior";
  const std::size_t plane = l.dims[0] * l.dims[1];
  bool any_rescaled = false;
  if (l.kind == DicomLayout::Kind::Philips) {
    io_detail::FilePtr f = io_detail::open_for_reading(path);
    const std::uint64_t offset = l.data_offset + std::uint64_t(frame.value_or(0)) * v.voxels();
    if (std::fseek(f.get(), long(offset), SEEK_SET) != 0) throw input_error(path, "cannot seek to the samples");
    std::vector<unsigned char> bytes(v.voxels());
    if (std::fread(bytes.data(), 1, bytes.size(), f.get()) != bytes.size())
      throw input_error(path, "data truncated while reading the samples");
    for (std::size_t i = 0; i < bytes.size(); ++i) v.data[i] = float(bytes[i]);
    return v;
  }
  const std::size_t per_file = l.kind == DicomLayout::Kind::Series ? plane : v.voxels();
  for (std::size_t k = 0; k < l.files.size(); ++k) {
    gdcm::ImageReader r;
    r.SetFileName(l.files[k].c_str());
    if (!r.Read()) throw input_error(l.files[k], "DICOM: the image cannot be read (damaged, or an unknown encoding)");
    const gdcm::Image& img = r.GetImage();
    const std::size_t frames = img.GetNumberOfDimensions() > 2 ? img.GetDimension(2) : 1;
    if (img.GetDimension(0) != l.dims[0] || img.GetDimension(1) != l.dims[1] ||
        std::size_t(img.GetDimension(0)) * img.GetDimension(1) * frames != per_file)
      throw input_error(l.files[k], "DICOM: the image's size differs from its header's");
    bool rescaled = false;
    decode_image(l.files[k], img, per_file, v.data.data() + k * per_file, &rescaled);
    any_rescaled = any_rescaled || rescaled;
  }
  // Rescaled samples (slope, intercept) are not the stored type's any more.
  if (any_rescaled) v.source_type = ScalarType::Float32;
  return v;
}

}  // namespace

// GDCM as Debian builds it keeps its assertions: a damaged file can abort
// the process inside GDCM (a truncated file meta group does). So every
// parse runs in a child process (fork): the child reads, the parent takes
// the result through a pipe; a child that dies is a one-line "damaged
// DICOM file" error, and an InputError in the child is passed on as one.
namespace {

struct Payload {
  VolumeHeader header;
  std::vector<float> data;  // empty for a header read
};

void put(std::string& b, const void* p, std::size_t n) {
  if (n > 0) b.append(static_cast<const char*>(p), n);
}
template <class T>
void put(std::string& b, const T& v) { put(b, &v, sizeof v); }
void put_text(std::string& b, const std::string& t) {
  put(b, std::uint64_t(t.size()));
  b += t;
}

struct Cursor {
  const std::string& b;
  std::size_t at = 0;
  void get(void* p, std::size_t n) {
    if (at + n > b.size()) throw std::runtime_error("DICOM child: short message");
    if (n == 0) return;  // p may be null (an empty sample vector)
    std::memcpy(p, b.data() + at, n);
    at += n;
  }
  template <class T>
  T get() { T v; get(&v, sizeof v); return v; }
  std::string text() {
    const auto n = get<std::uint64_t>();
    if (n > b.size() - at) throw std::runtime_error("DICOM child: short message");
    std::string t = b.substr(at, n);
    at += n;
    return t;
  }
};

std::string encode(const Payload& p) {
  std::string b;
  put(b, char('V'));
  const VolumeHeader& h = p.header;
  for (std::size_t d : h.dims) put(b, std::uint64_t(d));
  put(b, int(h.type));
  put(b, h.spacing);
  put(b, h.origin);
  put(b, h.frame.axes);
  put_text(b, h.frame.space);
  put(b, std::uint64_t(h.frames));
  put(b, std::uint64_t(h.files.size()));
  for (const std::string& f : h.files) put_text(b, f);
  put(b, std::uint64_t(p.data.size()));
  put(b, p.data.data(), p.data.size() * sizeof(float));
  return b;
}

Payload decode(const std::string& b) {
  Cursor c{b};
  if (c.get<char>() != 'V') throw std::runtime_error("DICOM child: bad message");
  Payload p;
  VolumeHeader& h = p.header;
  for (std::size_t& d : h.dims) d = std::size_t(c.get<std::uint64_t>());
  h.type = ScalarType(c.get<int>());
  h.spacing = c.get<Vec3d>();
  h.origin = c.get<Vec3d>();
  h.frame.axes = c.get<Mat3>();
  h.frame.space = c.text();
  h.frames = std::size_t(c.get<std::uint64_t>());
  const auto files = c.get<std::uint64_t>();
  for (std::uint64_t i = 0; i < files && i < 1000000; ++i) h.files.push_back(c.text());
  const auto n = c.get<std::uint64_t>();
  if (n > (b.size() - c.at) / sizeof(float)) throw std::runtime_error("DICOM child: short samples");
  p.data.resize(std::size_t(n));
  c.get(p.data.data(), p.data.size() * sizeof(float));
  return p;
}

bool write_all(int fd, const std::string& b) {
  std::size_t done = 0;
  while (done < b.size()) {
    const ssize_t w = ::write(fd, b.data() + done, b.size() - done);
    if (w < 0 && errno == EINTR) continue;
    if (w <= 0) return false;
    done += std::size_t(w);
  }
  return true;
}

// The child's data-segment limit (RLIMIT_DATA, which counts malloc's
// mappings too): its current size plus a budget from the input's size.
void limit_child_memory(const std::string& path) {
  std::uint64_t input = 0;
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    for (fs::directory_iterator it(path, ec), end; !ec && it != end; it.increment(ec)) {
      std::error_code e2;
      if (it->is_regular_file(e2)) input += it->file_size(e2);
    }
  } else {
    input = fs::file_size(path, ec);
  }
  std::uint64_t current_kb = 0;
  if (std::FILE* f = std::fopen("/proc/self/status", "r")) {
    char line[256];
    while (std::fgets(line, sizeof line, f))
      if (std::strncmp(line, "VmData:", 7) == 0) current_kb = std::strtoull(line + 7, nullptr, 10);
    std::fclose(f);
  }
  if (current_kb == 0) return;  // unknown: no limit rather than a wrong one
  const std::uint64_t budget = (std::uint64_t(1) << 30) + 32 * input;
  struct rlimit r {};
  r.rlim_cur = r.rlim_max = rlim_t(current_kb * 1024 + budget);
  ::setrlimit(RLIMIT_DATA, &r);
}

// Present only in sanitizer builds (weak: null otherwise).
extern "C" __attribute__((weak)) void __sanitizer_set_death_callback(void (*)(void));

template <class Fn>
Payload isolated(const std::string& path, Fn&& work) {
  int fds[2];
  if (::pipe(fds) != 0) throw input_error(path, "cannot create a pipe for the DICOM reader");
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw input_error(path, "cannot start the DICOM reader (fork failed)");
  }
  if (pid == 0) {  // the child: read, send, leave without running the parent's exit handlers
    ::close(fds[0]);
    // GDCM's assertion messages are not ours to print: the parent says what happened.
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) ::dup2(null, 2);
    // A fatal signal ends the child quietly (a fuzzer's or a sanitizer's
    // handlers would otherwise report the child's abort as their own).
    for (const int sig : {SIGABRT, SIGSEGV, SIGBUS, SIGFPE, SIGILL}) std::signal(sig, SIG_DFL);
    // Under a fuzzer, a sanitizer's report in the child would also run
    // libFuzzer's death callback, which saves the input as a crash- file:
    // the child's failure is the parent's answer, not a finding.
    if (&__sanitizer_set_death_callback != nullptr) __sanitizer_set_death_callback(nullptr);
    // GDCM allocates what an element's length declares before reading it: a
    // damaged length of gigabytes in a small file cost 30 s of zeroed pages.
    // The child may allocate what the input's bytes can describe: 1 GiB plus
    // 32 bytes per byte of input (float samples of compressed pixel data).
    limit_child_memory(path);
    std::string message;
    try {
      message = encode(work());
    } catch (const InputError& e) {
      message = std::string("E") + e.what();
    } catch (const std::bad_alloc&) {
      message = "E" + path + ": a damaged DICOM file: reading it needs more memory than its size allows (a wrong element length?)";
    } catch (const std::exception& e) {
      message = std::string("X") + e.what();
    } catch (...) {
      message = "Xunknown error";
    }
    ::_exit(write_all(fds[1], message) ? 0 : 1);
  }
  ::close(fds[1]);
  std::string reply;
  char chunk[1 << 16];
  for (;;) {
    const ssize_t r = ::read(fds[0], chunk, sizeof chunk);
    if (r < 0 && errno == EINTR) continue;
    if (r <= 0) break;
    reply.append(chunk, std::size_t(r));
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0 || reply.empty())
    throw input_error(path, "a damaged DICOM file: the DICOM library (GDCM) stopped on it" +
                                std::string(WIFSIGNALED(status) ? " (signal " + std::to_string(WTERMSIG(status)) + ")"
                                                                : ""));
  if (reply[0] == 'E') throw InputError(reply.substr(1));  // the child's one line, as it was
  if (reply[0] == 'X') throw std::runtime_error(reply.substr(1));
  return decode(reply);
}

}  // namespace

Volume read_dicom(const std::string& path, std::optional<std::size_t> frame) {
  const std::lock_guard<std::mutex> lock(gdcm_mutex());
  Payload p = isolated(path, [&] {
    const DicomLayout l = layout_of(path);
    check_frame(path, l, frame, false);
    Volume v = read_layout(path, l, frame);
    Payload out;
    out.header = header_of(l);
    out.header.type = v.source_type;
    out.data = std::move(v.data);
    return out;
  });
  Volume v(p.header.dims, p.header.spacing, p.header.type);
  if (p.data.size() != v.voxels()) throw std::runtime_error("DICOM child: sample count differs from the dims");
  v.origin = p.header.origin;
  v.frame.axes = p.header.frame.axes;
  v.frame.space = p.header.frame.space;
  v.data = std::move(p.data);
  return v;
}

VolumeHeader read_dicom_header(const std::string& path, std::optional<std::size_t> frame, bool any_frame) {
  const std::lock_guard<std::mutex> lock(gdcm_mutex());
  return isolated(path, [&] {
           const DicomLayout l = layout_of(path);
           check_frame(path, l, frame, any_frame);
           Payload out;
           out.header = header_of(l);
           return out;
         }).header;
}

}  // namespace softshell::io_detail
