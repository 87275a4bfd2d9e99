// The variational classifier's constants by name, for the studies' command
// lines (softshell_study_params --grid, softshell_study_shells --set): one
// table of names for both.
#pragma once

#include <string>

#include "variational.hpp"

namespace softshell {

// Sets the constant `key` of p to v; false for a name that is none of them.
inline bool set_variational_param(VariationalParams& p, const std::string& key, double v) {
  if (key == "alpha") p.alpha = v;
  else if (key == "beta") p.beta = v;
  else if (key == "gamma") p.gamma = v;
  else if (key == "omega") p.omega = v;
  else if (key == "delta") p.delta = v;
  else if (key == "epsilon") p.epsilon = v;
  else if (key == "u_ind") p.u_ind = v;
  else if (key == "sigma") p.sigma_mm = v;
  else if (key == "grad_sigma") p.grad_sigma_mm = v;
  else if (key == "kappa") p.kappa = v;
  else if (key == "shell") p.thickness_mm = v;
  else if (key == "edge_share") p.edge_share = v;
  else if (key == "edge_power") p.edge_power = v;
  else if (key == "edge_share_fine") p.edge_share_fine = v;
  else if (key == "edge_split") p.edge_split = v;
  else if (key == "edge_split_from") p.edge_split_from = v;
  else if (key == "profile_power") p.profile_power = v;
  else if (key == "sharpen") p.sharpen_iterations = int(v);
  else if (key == "sharpen_lambda") p.sharpen_lambda = v;
  else if (key == "sharpen_barrier") p.sharpen_barrier = v;
  else if (key == "max_gain") p.max_gain = v;
  else if (key == "shell_shift") p.shell_shift_mm = v;
  else return false;
  return true;
}

}  // namespace softshell
