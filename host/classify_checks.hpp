// The classifiers' parameters, checked before any work: a value the solver
// cannot use (not finite, out of its range, or beyond what float32 device
// arithmetic holds) is an InputError naming the option, exit 2. Shared by
// `classify`, the viewer and the fuzz harness of the pipeline.
#pragma once

#include "variational.hpp"

namespace softshell {

// All of VariationalParams but v_iso (see check_normalised_iso).
void check_variational_params(const VariationalParams& p);
void check_solver_params(const SolverParams& sp);
// v_iso after normalisation: within 1000 ranges of the data's [0, 1] (a
// typo otherwise, and the system's float32 coefficients would overflow).
// `iso_text` and `range` name the file value and the data's range.
void check_normalised_iso(double v_iso, const std::string& iso_text, const std::string& range);

}  // namespace softshell
