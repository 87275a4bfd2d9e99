// Host wrapper of kernels/stream.cl.
#include "stream.hpp"

namespace softshell {

Stream::Stream(Runtime& rt)
    : rt_(rt), copy_(rt.kernel("stream.cl", "stream_copy")), triad_(rt.kernel("stream.cl", "stream_triad")) {}

cl::Event Stream::copy(const cl::Buffer& a, const cl::Buffer& b, std::size_t n) const {
  copy_.setArg(0, a);
  copy_.setArg(1, b);
  copy_.setArg(2, static_cast<cl_ulong>(n));
  cl::Event e;
  rt_.queue().enqueueNDRangeKernel(copy_, cl::NullRange, rt_.global_1d(n), rt_.local_1d(), nullptr, &e);
  return e;
}

cl::Event Stream::triad(const cl::Buffer& a, const cl::Buffer& b, const cl::Buffer& c, float s,
                        std::size_t n) const {
  triad_.setArg(0, a);
  triad_.setArg(1, b);
  triad_.setArg(2, c);
  triad_.setArg(3, s);
  triad_.setArg(4, static_cast<cl_ulong>(n));
  cl::Event e;
  rt_.queue().enqueueNDRangeKernel(triad_, cl::NullRange, rt_.global_1d(n), rt_.local_1d(), nullptr, &e);
  return e;
}

}  // namespace softshell
