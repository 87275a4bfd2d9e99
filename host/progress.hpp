// Progress of long work on stderr (docs/robustness.md, "Progress").
//
// The CLI sets the mode once (host/cli/commands.cpp): by default a single
// line that rewrites itself when stderr is a terminal ("classify: solve
// 42 %, residual 3.1e-04 (tol 1e-04), 2.1 s, ETA 3 s"), nothing otherwise;
// `--quiet` or `--progress none` silence it, `--progress bar` forces the
// line, `--progress json` writes one JSON object per line:
//   {"stage":"classify/solve","event":"start|progress|end","elapsed_s":..,
//    "fraction":..,"eta_s":..,"detail":".."}
// (fraction, eta_s and detail only when known). Start and end events are
// always written; progress events at most every 0.2 s (0.1 s for the line).
// The line is cleared whenever a stage ends, so stdout and the final report
// stay clean.
//
// Stages nest (a stack): the label joins their names with '/'. The library
// opens stages where work is long (the solver's iterations, phantom
// generation); with the mode off every call returns at once.
#pragma once

#include <chrono>
#include <string>

namespace softshell::progress {

enum class Mode { Off, Line, Json };

void set_mode(Mode m);
Mode mode();

class Stage {
 public:
  explicit Stage(std::string name);
  ~Stage();
  Stage(const Stage&) = delete;
  Stage& operator=(const Stage&) = delete;

  // Share of the stage done, in [0, 1]; `detail` follows it on the line.
  void fraction(double f, const std::string& detail = "");
  // An iterative solve: the fraction is how far log(residual) has come from
  // the first residual reported toward log(tol).
  void residual(double r, double tol, int iteration);

 private:
  std::string name_;
  std::chrono::steady_clock::time_point t0_;
  double first_residual_ = -1;
  bool active_ = false;
};

}  // namespace softshell::progress
