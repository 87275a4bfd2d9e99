// Fixture for end-to-end tests of the `softshell` binary: a scratch
// directory per test, a runner that captures stdout and stderr separately,
// and the checks of the error contract (exit 2, one line naming the problem).
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern char** environ;

namespace softshell::test {

namespace fs = std::filesystem;

inline std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

struct RunResult {
  int status = -1;  // exit status, or -1 if the process did not exit normally
  int signal = 0;   // the signal that ended it, if one did
  std::string out, err;
  long max_rss_kb = 0;  // peak resident memory of the process
  double seconds = 0;   // wall time
};

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string pattern = (fs::path(::testing::TempDir()) / "softshell-cli-XXXXXX").string();
    std::vector<char> buf(pattern.begin(), pattern.end());
    buf.push_back('\0');
    ASSERT_NE(::mkdtemp(buf.data()), nullptr);
    dir_ = buf.data();
    // Captured output lives outside dir_, so listings of dir_ stay exact.
    std::string cap = (fs::path(::testing::TempDir()) / "softshell-cli-out-XXXXXX").string();
    std::vector<char> cbuf(cap.begin(), cap.end());
    cbuf.push_back('\0');
    ASSERT_NE(::mkdtemp(cbuf.data()), nullptr);
    capture_ = cbuf.data();
  }
  void TearDown() override {
    std::error_code ec;
    fs::permissions(dir_, fs::perms::owner_all, fs::perm_options::add, ec);
    fs::remove_all(dir_, ec);
    fs::remove_all(capture_, ec);
  }

  std::string file(const std::string& name) const { return (fs::path(dir_) / name).string(); }

  std::string write(const std::string& name, const std::string& bytes) const {
    std::ofstream out(file(name), std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    return file(name);
  }

  std::vector<std::string> listing() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

  // A running softshell (see start()); wait() collects it.
  struct Child {
    pid_t pid = -1;
    std::string out_path, err_path;
    std::chrono::steady_clock::time_point t0;
  };

  // Starts softshell with `args`, stdout and stderr captured to files; `env`
  // entries ("NAME=value") are added to (or override) this process's
  // environment; `program` replaces the softshell binary (then args[0] is
  // its first argument). `tag` keeps the captures of concurrent children
  // apart; `stdin_path` (optional) is opened as standard input.
  Child start(const std::vector<std::string>& args, const std::vector<std::string>& env = {},
              const std::string& tag = "", const std::string& program = SOFTSHELL_EXE,
              const std::string& stdin_path = "") const {
    Child c;
    c.out_path = capture_ + "/stdout" + tag;
    c.err_path = capture_ + "/stderr" + tag;
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, c.out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, c.err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (!stdin_path.empty()) posix_spawn_file_actions_addopen(&actions, 0, stdin_path.c_str(), O_RDONLY, 0);
    std::vector<std::string> argv_s{program};
    argv_s.insert(argv_s.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::vector<std::string> env_s;
    for (char** e = environ; *e; ++e) {
      const std::string entry = *e;
      const bool overridden = std::any_of(env.begin(), env.end(), [&](const std::string& o) {
        return entry.compare(0, o.find('=') + 1, o, 0, o.find('=') + 1) == 0;
      });
      if (!overridden) env_s.push_back(entry);
    }
    env_s.insert(env_s.end(), env.begin(), env.end());
    std::vector<char*> envp;
    for (std::string& e : env_s) envp.push_back(e.data());
    envp.push_back(nullptr);
    // The signals the tests send take their default action in the child,
    // whatever this process inherited (a background job ignores SIGINT).
    posix_spawnattr_t attr;
    posix_spawnattr_init(&attr);
    sigset_t defaults;
    sigemptyset(&defaults);
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&defaults, sig);
    posix_spawnattr_setsigdefault(&attr, &defaults);
    posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETSIGDEF);
    c.t0 = std::chrono::steady_clock::now();
    const int rc = posix_spawnp(&c.pid, program.c_str(), &actions, &attr, argv.data(), envp.data());
    posix_spawnattr_destroy(&attr);
    posix_spawn_file_actions_destroy(&actions);
    if (rc != 0) {
      c.pid = -1;
      std::ofstream(c.err_path) << "posix_spawn failed: " << std::strerror(rc);
    }
    return c;
  }

  static RunResult wait(const Child& c) {
    RunResult r;
    if (c.pid > 0) {
      int ws = 0;
      struct rusage ru {};
      while (::wait4(c.pid, &ws, 0, &ru) < 0 && errno == EINTR) {
      }
      r.status = WIFEXITED(ws) ? WEXITSTATUS(ws) : -1;
      r.signal = WIFSIGNALED(ws) ? WTERMSIG(ws) : 0;
      r.max_rss_kb = ru.ru_maxrss;
      r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - c.t0).count();
    }
    r.out = slurp(c.out_path);
    r.err = slurp(c.err_path);
    return r;
  }

  RunResult run(const std::vector<std::string>& args, const std::vector<std::string>& env = {}) const {
    return wait(start(args, env));
  }

  // Exit status 2 and one line "softshell: error: ..." containing `parts`.
  static void expect_one_line_error(const RunResult& r, std::initializer_list<std::string> parts) {
    EXPECT_EQ(r.status, 2) << "stderr: " << r.err;
    ASSERT_FALSE(r.err.empty());
    EXPECT_EQ(r.err.back(), '\n') << r.err;
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << "stderr is not one line:\n" << r.err;
    EXPECT_EQ(r.err.rfind("softshell: error: ", 0), 0u) << r.err;
    for (const std::string& p : parts) EXPECT_NE(r.err.find(p), std::string::npos) << "'" << p << "' not in: " << r.err;
  }

  void info_fails(const std::string& path, std::initializer_list<std::string> parts,
                  const std::vector<std::string>& extra = {}) const {
    std::vector<std::string> args{"info", path};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = run(args);
    SCOPED_TRACE("softshell info " + path);
    expect_one_line_error(r, parts);
    EXPECT_TRUE(r.out.empty()) << r.out;
  }

  std::string dir_, capture_;
};

}  // namespace softshell::test
