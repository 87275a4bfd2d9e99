// The `softshell` command-line front end: one function per subcommand,
// dispatched by run(). Errors are thrown (see error.hpp); main() maps them to
// messages and exit statuses.
#pragma once

namespace softshell::cli {

int run(int argc, char** argv);

}  // namespace softshell::cli
