// The fuzz harnesses' bodies (fuzz/fuzz_inputs.hpp) in the test suite: the
// seeds they start from are valid inputs that each reader accepts, and every
// regression input of tests/data/repro gets a documented answer from every
// harness. With SOFTSHELL_FUZZ_SEEDS=DIR set, the seeds are written to
// DIR/<harness>/ for libFuzzer (scripts/fuzz.sh).
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "fuzz_inputs.hpp"
#include "io.hpp"

namespace softshell {
namespace {

namespace fs = std::filesystem;

const char* const kHarnesses[] = {"nrrd", "metaimage", "raw", "nifti", "vti", "kretz", "dicom", "classify"};

bool run(const std::string& harness, const std::string& bytes) {
  const auto* p = reinterpret_cast<const std::uint8_t*>(bytes.data());
  if (harness == "nrrd") return fuzz::run_nrrd(p, bytes.size());
  if (harness == "metaimage") return fuzz::run_metaimage(p, bytes.size());
  if (harness == "raw") return fuzz::run_raw(p, bytes.size());
  if (harness == "nifti") return fuzz::run_nifti(p, bytes.size());
  if (harness == "vti") return fuzz::run_vti(p, bytes.size());
  if (harness == "kretz") return fuzz::run_kretz(p, bytes.size());
  if (harness == "dicom") return fuzz::run_dicom(p, bytes.size());
  return fuzz::run_classify(p, bytes.size());
}

TEST(FuzzSeeds, EverySeedIsAcceptedAndWritten) {
  const char* env = std::getenv("SOFTSHELL_FUZZ_SEEDS");
  const fs::path root = env && *env ? fs::path(env) : fs::path(::testing::TempDir()) / "softshell-fuzz-seeds";
  for (const char* harness : kHarnesses) {
    if (std::string(harness) == "nifti" && !nifti_supported()) continue;  // a build without niftilib
    if (std::string(harness) == "dicom" && !dicom_supported()) continue;  // a build without GDCM
    const auto seeds = fuzz::seeds(harness);
    EXPECT_GE(seeds.size(), 4u) << harness;
    fs::create_directories(root / harness);
    for (const auto& s : seeds) {
      SCOPED_TRACE(std::string(harness) + " seed " + s.name);
      // A seed the harness refuses would only teach the fuzzer an error path.
      EXPECT_TRUE(run(harness, s.bytes));
      std::ofstream(root / harness / s.name, std::ios::binary).write(s.bytes.data(), std::streamsize(s.bytes.size()));
      EXPECT_EQ(fs::file_size(root / harness / s.name), s.bytes.size());
    }
  }
  if (!(env && *env)) fs::remove_all(root);
}

// Every file of tests/data/repro through every harness: a documented answer
// (a crash or a broken invariant aborts the test binary).
TEST(FuzzRegression, ReproInputsGetDocumentedAnswers) {
  const fs::path repro = fs::path(SOFTSHELL_SOURCE_DIR) / "tests" / "data" / "repro";
  int files = 0;
  for (const auto& e : fs::directory_iterator(repro)) {
    std::ifstream in(e.path(), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    ++files;
    for (const char* harness : kHarnesses) {
      SCOPED_TRACE(std::string(harness) + " on " + e.path().filename().string());
      run(harness, bytes);
    }
  }
  EXPECT_GE(files, 24);
}

}  // namespace
}  // namespace softshell
