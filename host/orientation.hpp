// Splat orientation by the structure tensor of the opacity u (the default
// orientation of the splat renderer; kernels/orientation.h has the definition
// and the reason; docs/rendering.md, "Splat normals").
#pragma once

#include <array>
#include <vector>

#include "cl_runtime.hpp"
#include "volume.hpp"

namespace softshell {

// The renderer's default structure-tensor sigma, in voxels.
constexpr double kDefaultTensorSigma = 1.5;

// Host reference in double precision, the same definition as the device's
// tensor_orientation: at point p (voxel coordinates, voxel centres at
// integers), the principal eigenvector of the Gaussian-weighted structure
// tensor of u, scaled by the rms gradient along it (per mm); 0 where u is
// flat. Throws std::invalid_argument for sigma <= 0 or an empty volume.
std::array<double, 3> tensor_orientation_reference(const Volume& u, const std::array<double, 3>& p, double sigma);

// The field whose structure tensor orients splats "by the data"
// (SplatNormals::Data, `render --orientation data`): the B-mode volume
// Gaussian-lowpassed by sigma = its finest spacing (one voxel along the
// finest axis, isotropic in mm), clamp-to-edge, float. The lowpass is the
// tensor's inner scale: speckle's gradients are as strong as the surfaces'
// and point anywhere; a voxel's blur leaves the surfaces' and removes most of
// theirs. The orientation of a surface in the data does not depend on how
// well u drew it (docs/rendering.md, "Splat normals"). Same dims, spacing,
// origin and frame as `bmode`. Throws InputError for an empty volume.
inline constexpr double kDataLowpassVoxels = 1.0;
Volume data_orientation_field(const Volume& bmode, int threads = 0);

// The same on the device at many points: uploads u, one work-item per point.
// Throws InputError unless 0 < sigma <= 8 (the kernel's window holds radius
// ceil(2 sigma) <= 16).
std::vector<std::array<float, 3>> tensor_orientation_device(Runtime& rt, const Volume& u,
                                                            const std::vector<std::array<float, 3>>& points,
                                                            double sigma);

}  // namespace softshell
