// Parameter checks of the classifiers (host/classify_checks.hpp).
#include "classify_checks.hpp"

#include <cmath>

#include "error.hpp"

namespace softshell {

void check_variational_params(const VariationalParams& p) {
  const auto finite = [](double x) { return std::isfinite(x); };
  if (!finite(p.alpha) || !finite(p.beta) || !finite(p.gamma) || !finite(p.omega) || !finite(p.delta) ||
      !finite(p.epsilon) || !finite(p.u_ind) || !finite(p.kappa) || !finite(p.grad_sigma_mm) || !finite(p.sigma_mm))
    throw InputError("--alpha, --beta, --gamma, --omega, --delta, --epsilon, --u-ind, --kappa, --sigma and "
                     "--grad-sigma must be finite numbers");
  if (!(p.gamma * p.delta > 0)) throw InputError("--gamma and --delta must be > 0 (the system is singular otherwise)");
  if (p.alpha < 0 || p.beta < 0) throw InputError("--alpha and --beta must be >= 0");
  if (!(p.epsilon > 0)) throw InputError("--epsilon must be > 0");
  if (!(p.sigma_mm >= 0)) throw InputError("--sigma must be >= 0");
  if (!(p.grad_sigma_mm >= 0)) throw InputError("--grad-sigma must be >= 0");
  if (!(p.kappa >= 0)) throw InputError("--kappa must be >= 0");
  if (p.omega < 0 || p.omega > 1 || p.delta > 1) throw InputError("--omega and --delta must be in [0, 1]");
  // float32 on the device: weights beyond 1e6 overflow the system's
  // coefficients (u_ind enters squared), and below 1e-6 epsilon is 0 next
  // to |grad v|^2.
  if (p.alpha > 1e6 || p.beta > 1e6 || p.gamma > 1e6 || p.kappa > 1e6 || std::fabs(p.u_ind) > 1e6 ||
      p.epsilon > 1e6 || p.epsilon < 1e-6)
    throw InputError("--alpha, --beta, --gamma, --kappa and |--u-ind| must be at most 1e6, --epsilon in [1e-6, 1e6]");
  // The shell functional (docs/numerics.md).
  if (!(p.thickness_mm >= 0) || !std::isfinite(p.thickness_mm) || p.thickness_mm > 1e3)
    throw InputError("--shell must be a finite number in [0, 1000] (mm)");
  if (!(p.profile_power >= 1 && p.profile_power <= 4)) throw InputError("--profile-power must be in [1, 4]");
  if (!(p.edge_share >= 0 && p.edge_share <= 0.5)) throw InputError("--edge-share must be in [0, 0.5]");
  if (!(p.edge_power >= 0 && p.edge_power <= 8)) throw InputError("--edge-power must be in [0, 8]");
  if (!(p.edge_split >= 0 && p.edge_split <= 100)) throw InputError("--edge-split must be in [0, 100]");
  if (!(p.edge_split_from >= 0 && p.edge_split_from <= 100)) throw InputError("--edge-split-from must be in [0, 100]");
  if (!(p.edge_share_fine >= 0 && p.edge_share_fine <= 0.5)) throw InputError("edge_share_fine must be in [0, 0.5]");
  if (!(p.shell_shift_mm >= 0 && p.shell_shift_mm <= 10)) throw InputError("--shell-shift must be in [0, 10] mm");
  if (!(p.weight_cap >= 1 && p.weight_cap <= 1e12)) throw InputError("--weight-cap must be in [1, 1e12]");
  if (p.sharpen_iterations < 0 || p.sharpen_iterations > 10) throw InputError("--sharpen must be in [0, 10]");
  if (!(p.sharpen_lambda >= 0 && p.sharpen_lambda <= 1e6)) throw InputError("--sharpen-lambda must be in [0, 1e6]");
  if (!(p.sharpen_barrier >= 0.05 && p.sharpen_barrier <= 1)) throw InputError("--sharpen-barrier must be in [0.05, 1]");
  if (!(p.max_gain >= 0 && p.max_gain <= 100)) throw InputError("--max-gain must be in [0, 100]");
  const CrestParams& c = p.crest;
  if (!(c.ridge >= 0 && c.ridge <= 1)) throw InputError("--echo-crest must be in [0, 1]");
  if (!(c.quantile > 0 && c.quantile < 1) || !(c.reach_mm > 0 && c.reach_mm <= 100) ||
      !(c.above_mm > 0 && c.above_mm <= 100) || !(c.pad_mm >= 0 && c.pad_mm <= 100) ||
      !(c.min_edge >= 0 && c.min_edge <= 100) || !(c.lift >= 0 && c.lift <= 100) || c.axis < 0 || c.axis > 2)
    throw InputError("the echo-crest rule's quantile must be in (0, 1), its lengths in (0, 100] mm, its edge share and lift in "
                     "[0, 100] and its axis x, y or z");
}

void check_solver_params(const SolverParams& sp) {
  if (!(sp.tol > 0) || sp.tol >= 1) throw InputError("--tol must be in (0, 1)");
  if (sp.max_cycles < 1 || sp.max_levels < 1) throw InputError("--max-cycles and --levels must be >= 1");
  if (sp.max_cycles > 100000 || sp.max_levels > 64) throw InputError("--max-cycles must be at most 100000, --levels 64");
}

void check_normalised_iso(double v_iso, const std::string& iso_text, const std::string& range) {
  if (!(std::fabs(v_iso) <= 1e3))
    throw InputError("--iso " + iso_text + " is far outside the data's intensity range (" + range + ")");
}

}  // namespace softshell
