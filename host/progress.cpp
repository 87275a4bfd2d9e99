// Progress of long work on stderr (host/progress.hpp).
#include "progress.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <vector>

namespace softshell::progress {
namespace {

using Clock = std::chrono::steady_clock;

struct State {
  std::mutex mutex;
  Mode mode = Mode::Off;
  std::vector<std::string> stack;  // open stages, outermost first
  Clock::time_point last_emit{};
  bool line_shown = false;
};

State& state() {
  static State s;
  return s;
}

std::string label(const State& s) {
  std::string l;
  for (const std::string& n : s.stack) l += (l.empty() ? "" : "/") + n;
  return l;
}

std::string json_string(const std::string& text) {
  std::string o = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') o += '\\', o += c;
    else if (static_cast<unsigned char>(c) < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      o += buf;
    } else {
      o += c;
    }
  }
  return o + "\"";
}

std::string number(double v, const char* format) {
  char buf[32];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string duration(double s) {
  if (s < 60) return number(s, s < 10 ? "%.1f s" : "%.0f s");
  return number(std::floor(s / 60), "%.0f min ") + number(std::fmod(s, 60.0), "%.0f s");
}

// Writes one event; `fraction` < 0: unknown. Caller holds the mutex.
void emit(State& s, const char* event, double elapsed, double fraction, const std::string& detail) {
  const double eta = fraction > 0.02 && fraction < 1 ? elapsed * (1 - fraction) / fraction : -1;
  if (s.mode == Mode::Json) {
    std::string line = "{\"stage\":" + json_string(label(s)) + ",\"event\":\"" + event +
                       "\",\"elapsed_s\":" + number(elapsed, "%.3f");
    if (fraction >= 0) line += ",\"fraction\":" + number(fraction, "%.4f");
    if (eta >= 0) line += ",\"eta_s\":" + number(eta, "%.1f");
    if (!detail.empty()) line += ",\"detail\":" + json_string(detail);
    line += "}\n";
    std::fputs(line.c_str(), stderr);
  } else {
    std::string line = "\r\033[K" + label(s);
    if (fraction >= 0) line += number(100 * fraction, " %3.0f %%");
    if (!detail.empty()) line += ", " + detail;
    line += ", " + duration(elapsed);
    if (eta >= 0) line += ", ETA " + duration(eta);
    std::fputs(line.c_str(), stderr);
    s.line_shown = true;
  }
  std::fflush(stderr);
  s.last_emit = Clock::now();
}

}  // namespace

void set_mode(Mode m) {
  std::lock_guard<std::mutex> lock(state().mutex);
  state().mode = m;
}

Mode mode() {
  std::lock_guard<std::mutex> lock(state().mutex);
  return state().mode;
}

Stage::Stage(std::string name) : name_(std::move(name)), t0_(Clock::now()) {
  State& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  if (s.mode == Mode::Off) return;
  active_ = true;
  s.stack.push_back(name_);
  emit(s, "start", 0.0, -1, "");
}

Stage::~Stage() {
  if (!active_) return;
  State& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  const double elapsed = std::chrono::duration<double>(Clock::now() - t0_).count();
  if (s.mode == Mode::Json) emit(s, "end", elapsed, -1, "");
  // Unwound out of order (an exception): drop everything above this stage.
  const auto it = std::find(s.stack.rbegin(), s.stack.rend(), name_);
  if (it != s.stack.rend()) s.stack.erase(std::next(it).base(), s.stack.end());
  if (s.mode == Mode::Line && s.line_shown) {
    // Cleared at the end of every stage: what a command prints to stdout
    // after a stage starts on a clean line.
    std::fputs("\r\033[K", stderr);
    std::fflush(stderr);
    s.line_shown = false;
  }
}

void Stage::fraction(double f, const std::string& detail) {
  if (!active_) return;
  State& s = state();
  std::lock_guard<std::mutex> lock(s.mutex);
  const auto now = Clock::now();
  const double since = std::chrono::duration<double>(now - s.last_emit).count();
  if (since < (s.mode == Mode::Json ? 0.2 : 0.1)) return;
  emit(s, "progress", std::chrono::duration<double>(now - t0_).count(), std::clamp(f, 0.0, 1.0), detail);
}

void Stage::residual(double r, double tol, int iteration) {
  if (!active_) return;
  if (first_residual_ < 0) first_residual_ = r;
  double f = 0;
  if (first_residual_ > tol && r > 0 && tol > 0) f = std::log(first_residual_ / r) / std::log(first_residual_ / tol);
  if (!(r > tol)) f = 1;
  fraction(std::isfinite(f) ? f : 0.0,
           "iteration " + std::to_string(iteration) + ", residual " + number(r, "%.2e") + " (tol " + number(tol, "%.0e") + ")");
}

}  // namespace softshell::progress
