// Shared pieces of the CLI's commands: how a command registers itself,
// options that several commands take, and timing helpers.
//
// Each command lives in its own cmd_<name>.cpp with one entry point,
// add_<name>_command(app, action): it adds its subcommand and options to the
// app and, when the subcommand is given, stores in `action` the work to run
// after parsing. Validation failures throw InputError (exit 2).
#pragma once

#include <CLI/CLI.hpp>
#include <chrono>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "io.hpp"

namespace softshell {
class Runtime;
}  // namespace softshell

namespace softshell::cli {

using Action = std::function<int()>;

void add_bench_command(CLI::App& app, Action& action);
void add_classify_command(CLI::App& app, Action& action);
void add_devices_command(CLI::App& app, Action& action);
void add_evaluate_command(CLI::App& app, Action& action);
void add_figure2_command(CLI::App& app, Action& action);
void add_info_command(CLI::App& app, Action& action);
void add_lowpass_command(CLI::App& app, Action& action);
void add_mesh_command(CLI::App& app, Action& action);
void add_phantom_command(CLI::App& app, Action& action);
void add_slices_command(CLI::App& app, Action& action);
void add_synthetic_command(CLI::App& app, Action& action);
#ifdef SOFTSHELL_HAVE_VIEWER
// In the viewer library (viewer/CMakeLists.txt): OpenGL rendering commands.
void add_render_command(CLI::App& app, Action& action);
void add_view_command(CLI::App& app, Action& action);
// cmd_figures.cpp: the paper's Figures 5 and 6, and `render --method raycast`.
void add_figure5_command(CLI::App& app, Action& action);
void add_figure6_command(CLI::App& app, Action& action);
// For `softshell bench` (Table 1's render columns, host/bench.hpp RenderTimer):
// the median seconds per frame of `method` ("splat": oriented splats, the
// figure's splat panel; "shearwarp": VolPack) on u, viewed down the beam;
// nullopt when the renderer is unavailable (no display, no VolPack).
std::optional<double> bench_render_seconds(Runtime& rt, const Volume& u, const std::string& method, int width,
                                           int height);
struct RaycastRenderOptions;  // the ray caster's own options on `render`
std::shared_ptr<RaycastRenderOptions> add_raycast_render_options(CLI::App* sub);
struct RaycastRenderRequest {  // `render`'s common options
  std::string in, out, device, size, view, crop, iso;
  int turntable = 0, benchmark = 0;
  bool quiet = false, opacity = false, classify = false;
};
int run_raycast_render(const RaycastRenderOptions& o, const RaycastRenderRequest& request);
// cmd_render_methods.cpp: `render --method mc` (Marching Cubes at --level, drawn with GL) and
// `render --method shearwarp` (VolPack).
int run_mesh_render(double level, const RaycastRenderRequest& request);
int run_shearwarp_render(const RaycastRenderRequest& request);
#endif

// A sequence given as files (docs/formats.md, "3D+t sequences"): the
// command line's inputs, each a file or a quoted glob pattern (* ? [..]:
// expanded here, in natural order, so frame2 comes before frame10), in the
// order given. Throws InputError for a pattern that matches nothing.
std::vector<std::string> expand_input_files(const std::vector<std::string>& args);
// The per-frame output path of PATTERN for frame k of n: its one run of '#'
// replaced by k, zero-padded to the run's length (or to n - 1's digits).
std::string frame_path(const std::string& pattern, std::size_t k, std::size_t n);
// Checks a --per-frame-files pattern (exactly one run of '#', a volume
// output extension); throws InputError naming `option`.
void check_frame_pattern(const std::string& pattern, const std::string& option);

// --raw / --type / --spacing / --big-endian for headerless input.
struct RawOptions {
  std::string dims, type, spacing;
  bool big_endian = false;
  std::optional<std::size_t> frame;  // --frame K: one frame of a 3D+t sequence

  void add_to(CLI::App* app);
  // The raw description, or nullopt when --raw was not given; throws
  // InputError on inconsistent or malformed options.
  std::optional<RawSpec> spec() const;
};

// --replace-non-finite V: what a command does with NaN and infinite samples.
// By default they are refused (exit 2, the first one named): every stage
// downstream (lowpass, normalisation, the solver) would turn one of them
// into NaN everywhere. With V they become V (in the file's units).
struct NonFiniteOption {
  std::optional<double> value;

  void add_to(CLI::App* app);
  // Refuses or replaces; `path` names the file in the message.
  void apply(Volume& v, const std::string& path) const;
};

// --device I|NAME, documented the same way everywhere.
void add_device_option(CLI::App* app, std::string& device);

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace softshell::cli
