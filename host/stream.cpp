// Host wrapper of kernels/stream.cl.
#include "stream.hpp"

namespace softshell {

Stream::Stream(Runtime& rt)
    : rt_(rt), copy_(rt.kernel("stream.cl", "stream_copy")), triad_(rt.kernel("stream.cl", "stream_triad")) {}

cl::Event Stream::copy(const cl::Buffer& a, const cl::Buffer& b, std::size_t n) const {
  Runtime::set_args(copy_, a, b, static_cast<cl_ulong>(n));
  return rt_.enqueue_1d(copy_, n);
}

cl::Event Stream::triad(const cl::Buffer& a, const cl::Buffer& b, const cl::Buffer& c, float s,
                        std::size_t n) const {
  Runtime::set_args(triad_, a, b, c, s, static_cast<cl_ulong>(n));
  return rt_.enqueue_1d(triad_, n);
}

}  // namespace softshell
