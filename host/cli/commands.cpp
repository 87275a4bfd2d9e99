// The `softshell` command-line front end: builds the CLI11 app from the
// commands (cmd_*.cpp), parses, and runs the chosen one. Errors are thrown
// (see error.hpp); main() maps them to messages and exit statuses.
#include "commands.hpp"

#include <CLI/CLI.hpp>
#include <unistd.h>
#include <set>
#include <string>

#include "cli_common.hpp"
#include "cli_validate.hpp"
#include "error.hpp"
#include "progress.hpp"

namespace softshell::cli {

int run(int argc, char** argv) {
  CLI::App app{
      "softshell: variational opacity classification and oriented-splat rendering of 3D ultrasound on OpenCL "
      "devices.",
      "softshell"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "softshell 0.1.0");
  app.footer("Exit status: 0 ok, 2 bad input or no device, 3 not converged, 1 internal error.");

  // One line per command; each lives in its own cmd_<name>.cpp.
  Action action;
  add_devices_command(app, action);
  add_info_command(app, action);
  add_lowpass_command(app, action);
  add_phantom_command(app, action);
  add_classify_command(app, action);
  add_evaluate_command(app, action);
  add_figure2_command(app, action);
  add_mesh_command(app, action);
  add_slices_command(app, action);
  add_synthetic_command(app, action);
#ifdef SOFTSHELL_HAVE_VIEWER
  add_render_command(app, action);
  add_view_command(app, action);
  add_figure5_command(app, action);
  add_figure6_command(app, action);
#endif
  add_bench_command(app, action);
  // --progress on the commands that can take more than a second
  // (host/progress.hpp).
  std::string progress = "auto";
  for (CLI::App* sub : app.get_subcommands([](const CLI::App* a) { return !a->get_name().empty(); })) {
    static const std::set<std::string> slow{"classify", "lowpass", "mesh",   "phantom", "figure2",
                                            "render",   "view",    "figure5", "figure6"};
    if (slow.count(sub->get_name()))
      sub->add_option("--progress", progress,
                      "Progress on stderr: auto (a self-rewriting line when stderr is a terminal, unless --quiet), "
                      "none, bar (the line even when not a terminal) or json (one JSON object per line)")
          ->capture_default_str()
          ->check(one_of({"auto", "none", "bar", "json"}));
  }
  // Every floating-point option refuses NaN and infinities, ranged or not
  // (cli_validate.hpp).
  require_checked_numbers(app);

  // CLI11 reports a misspelt command as "a subcommand is required"; name it.
  if (argc > 1 && argv[1][0] != '-') {
    std::string known;
    bool found = false;
    for (const CLI::App* sub : app.get_subcommands({})) {
      found = found || sub->get_name() == argv[1];
      known += (known.empty() ? "" : ", ") + sub->get_name();
    }
    if (!found) throw InputError(std::string("unknown command '") + argv[1] + "' (commands: " + known + ")");
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::string msg = e.what();
    for (char& ch : msg)
      if (ch == '\n') ch = ' ';
    throw InputError(msg + " (see softshell --help)");
  }

  if (!action) throw InputError("no command given (see softshell --help)");
  bool quiet = false;
  for (const CLI::App* sub : app.get_subcommands()) {
    const CLI::Option* q = sub->get_option_no_throw("--quiet");
    quiet = quiet || (q && q->count() > 0);
  }
  progress::set_mode(progress == "json"  ? progress::Mode::Json
                     : progress == "bar" ? progress::Mode::Line
                     : progress == "none" || quiet || !::isatty(STDERR_FILENO) ? progress::Mode::Off
                                                                               : progress::Mode::Line);
  return action();
}

}  // namespace softshell::cli
