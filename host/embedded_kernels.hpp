// The OpenCL sources of kernels/, embedded at build time by
// cmake/embed_kernels_script.cmake (generated embedded_kernels.cpp).
#pragma once

#include <string_view>
#include <vector>

namespace softshell {

struct EmbeddedKernel {
  std::string_view name;    // file name in kernels/, e.g. "filter.cl"
  std::string_view source;  // verbatim file content
  std::string_view hash;    // first 16 hex digits of the file's SHA-256
};

const std::vector<EmbeddedKernel>& embedded_kernels();

}  // namespace softshell
