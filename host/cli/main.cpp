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
#include "io.hpp"

namespace {

int fail(const std::string& message, int status) {
  std::cerr << "softshell: error: " << message << '\n';
  return status;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace softshell;
  // Before anything else (PoCL, LLVM) touches signals: temporaries are
  // removed on SIGINT / SIGTERM / SIGHUP unless those are ignored (nohup, a
  // background job), and a write beyond ulimit -f fails with EFBIG, one
  // line, instead of SIGXFSZ killing the process (host/io.hpp).
  io_detail::install_signal_cleanup();
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
