// softshell entry point: runs the CLI and turns every failure into one clear
// message and a documented exit status:
//   0 success, 2 bad input / usage / no device, 3 solver did not converge,
//   1 internal or device runtime failure.
#include <csignal>
#include <iostream>
#include <new>

#include "cl_runtime.hpp"
#include "commands.hpp"
#include "error.hpp"

namespace {

int fail(const std::string& message, int status) {
  std::cerr << "softshell: error: " << message << '\n';
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace softshell;
  // A write beyond RLIMIT_FSIZE (ulimit -f) then fails with EFBIG, reported
  // in one line, instead of killing the process; PoCL's kernel cache writes
  // fail the same way.
  struct sigaction xfsz {};
  if (::sigaction(SIGXFSZ, nullptr, &xfsz) == 0 && xfsz.sa_handler == SIG_DFL) std::signal(SIGXFSZ, SIG_IGN);
  try {
    return cli::run(argc, argv);
  } catch (const InputError& e) {
    return fail(e.what(), 2);
  } catch (const DeviceError& e) {
    return fail(e.what(), 2);
  } catch (const NotConvergedError& e) {
    return fail(e.what(), 3);
  } catch (const KernelBuildError& e) {
    std::cerr << "softshell: error: " << e.what() << "\n--- build log ---\n" << e.log() << "\n--- end of build log ---\n";
    return 1;
  } catch (const cl::Error& e) {
    return fail(std::string("OpenCL call ") + e.what() + " failed: " + cl_error_name(e.err()) + " (" +
                    std::to_string(e.err()) + ")",
                1);
  } catch (const std::bad_alloc&) {
    return fail("out of host memory", 1);
  } catch (const std::exception& e) {
    return fail(std::string("internal error: ") + e.what(), 1);
  }
}
