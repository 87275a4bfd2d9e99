// The fuzz harnesses' bodies (docs/robustness.md, "Fuzzing"), in a library
// so the test suite runs the same code on the seeds and the regression
// inputs (tests/test_fuzz_inputs.cpp) that libFuzzer starts from
// (fuzz/fuzz_*.cpp, scripts/fuzz.sh).
//
// Each run_*() takes one fuzzer input, feeds it to softshell's own code as
// a user's file or parameters would, and returns normally when softshell
// answered as documented: a result that passes the checks below (returns
// true), or an InputError / NotConvergedError (exit 2 / 3 in the CLI;
// returns false). Anything else -- another exception (exit 1, "internal
// error"), a broken invariant -- calls std::abort(), which libFuzzer reports
// as a crash with the input saved.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace softshell::fuzz {

// Splits an input at the first kDataSeparator: the header file, and (when
// present) its detached data file "v.raw" beside it.
inline constexpr char kDataSeparator[] = "\xff" "DAT";

// NRRD: without a separator the input is "v.nrrd"; with one, "v.nhdr" and
// "v.raw". Reads the header and the volume; a volume that reads is checked
// (dims, spacing, header agreement) and written back as .nrrd, .mha and
// .mhd (plain and compressed) and read again: the samples must survive.
bool run_nrrd(const std::uint8_t* data, std::size_t size);
// MetaImage: "v.mha", or "v.mhd" + "v.raw"; the same checks.
bool run_metaimage(const std::uint8_t* data, std::size_t size);
// Headerless raw data: the first 8 bytes choose the sample type, byte
// order, dims (1..16 each) and spacing; the rest is the file. The first
// line (up to 64 bytes) is also given to the --raw / --spacing parsers.
bool run_raw(const std::uint8_t* data, std::size_t size);
// NIfTI: "v.nii" (NIfTI-1 or -2, plain or gzip), or with a separator the
// header "v.hdr" and its data "v.img"; the same checks. Without NIfTI in the
// build every input is refused (returns false).
bool run_nifti(const std::uint8_t* data, std::size_t size);
// VTK XML ImageData: "v.vti"; the same checks.
bool run_vti(const std::uint8_t* data, std::size_t size);
// GE Kretz .vol: "v.vol"; the same checks (the scan conversion included).
bool run_kretz(const std::uint8_t* data, std::size_t size);
// DICOM: "v.dcm" through GDCM (a multi-frame volume, or Philips' Cartesian
// 3D+t file); the same checks. Without DICOM in the build every input is
// refused (returns false).
bool run_dicom(const std::uint8_t* data, std::size_t size);
// The classify pipeline on a tiny volume (dims 3..8 per axis): the first
// kClassifyHeader bytes choose dims, spacing, sample type, the method, the
// mask rule, the near-field removal, the isovalue (a value, or auto by the
// local rule with or without its field, the echo ridge or the edge) and
// the parameters (the shell functional's, sharpening included, or the
// paper's functional; small volumes' length scales; the echo-crest ridge); the rest are the samples. Runs what `softshell
// classify` runs (checks, mask, near field, automatic isovalue, unscanned
// fill, levelling by the isovalue field, the variational or Levoy
// classifier with at most 20 iterations) on one OpenCL runtime per
// process; the opacity must be finite and in [0, 1].
constexpr std::size_t kClassifyHeader = 48;
bool run_classify(const std::uint8_t* data, std::size_t size);

// A NIfTI file's bytes, written field by field (no niftilib here): what the
// seeds and the tests (tests/test_nifti.cpp) feed the reader.
struct NiftiSpec {
  int version = 1;                                          // 1 or 2
  std::int64_t dim[8] = {3, 2, 2, 2, 1, 1, 1, 1};
  int datatype = 2;                                         // DT_UINT8
  int bitpix = 8;
  double pixdim[8] = {1, 1, 1, 1, 1, 1, 1, 1};              // pixdim[0]: qfac
  double scl_slope = 0, scl_inter = 0;
  int qform_code = 0, sform_code = 0;
  double quatern[3] = {0, 0, 0}, qoffset[3] = {0, 0, 0};
  double srow[3][4] = {{0, 0, 0, 0}, {0, 0, 0, 0}, {0, 0, 0, 0}};
  int xyzt_units = 2;                                       // NIFTI_UNITS_MM
  bool big_endian = false;
  bool pair = false;  // magic "ni1"/"ni2": header only, the data in a .img file
};
// The header (and, for a single file, the 4 bytes to vox_offset), without samples.
std::string nifti_header(const NiftiSpec& spec);

// A DICOM Part 10 file's bytes, written element by element (explicit VR
// little endian; no GDCM here): what the seeds and the tests
// (tests/test_dicom.cpp) feed the reader. An element's value is given
// encoded (dicom_text, dicom_u16, dicom_f64, a sequence's items, ...);
// odd lengths are padded as the VR requires and elements sorted by tag.
struct DicomElement {
  std::uint16_t group = 0, element = 0;
  std::string vr;     // "UI", "US", "DS", "SQ", "OB", ...
  std::string value;  // encoded bytes; for SQ, dicom_items(...)
};
std::string dicom_file(const std::string& sop_class, std::vector<DicomElement> elements);
std::string dicom_items(const std::vector<std::vector<DicomElement>>& items);  // an SQ's value
std::string dicom_u16(std::uint16_t v);
std::string dicom_f64(const std::vector<double>& v);
std::string dicom_f32(const std::vector<float>& v);
std::string dicom_ds(const std::vector<double>& v);  // decimal strings joined by '\'

// Seed inputs per harness, as files: name -> bytes. Valid files of every
// kind each reader takes (every NRRD encoding, attached and detached,
// MetaImage plain and compressed, each raw type) and a few classify setups.
struct Seed {
  std::string name;
  std::string bytes;
};
std::vector<Seed> seeds(const std::string& harness);  // "nrrd", "metaimage", "raw", "nifti", "vti", "kretz", "dicom", "classify"

}  // namespace softshell::fuzz
