// Error types shared by the library and the CLI. main() maps each to an exit
// status: InputError and DeviceError -> 2 (the user can fix it),
// NotConvergedError -> 3, KernelBuildError / cl::Error / others -> 1.
#pragma once

#include <stdexcept>
#include <string>

namespace softshell {

// Bad argument or bad input file. The message is one line and names the
// file (or option) and the problem, e.g. "vol.nrrd: data truncated: ...".
struct InputError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// No OpenCL platform, no device matching the request, or a volume the device
// cannot hold. One line; says what was found and what to do.
struct DeviceError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// An OpenCL program failed to build. what() is a one-line summary; log() is
// the full build log of the device.
class KernelBuildError : public std::runtime_error {
 public:
  KernelBuildError(const std::string& summary, std::string log)
      : std::runtime_error(summary), log_(std::move(log)) {}
  const std::string& log() const { return log_; }

 private:
  std::string log_;
};

// An iterative solve stopped before reaching its tolerance.
struct NotConvergedError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Builds "<path>: <problem>" for InputError messages.
inline InputError input_error(const std::string& path, const std::string& problem) {
  return InputError(path + ": " + problem);
}

}  // namespace softshell
