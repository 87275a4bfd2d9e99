// libFuzzer harness: softshell::fuzz::run_dicom (fuzz/fuzz_inputs.hpp says what it
// feeds and checks). Built with SOFTSHELL_FUZZ=ON; scripts/fuzz.sh runs it.
#include <cstddef>
#include <cstdint>

#include "fuzz_inputs.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  softshell::fuzz::run_dicom(data, size);
  return 0;
}
