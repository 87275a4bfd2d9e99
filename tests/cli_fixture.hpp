// Fixture for end-to-end tests of the `softshell` binary: a scratch
// directory per test, a runner that captures stdout and stderr separately,
// and the checks of the error contract (exit 2, one line naming the problem).
#pragma once

#include <fcntl.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
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
  std::string out, err;
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

  // Runs softshell with `args`, stdout and stderr captured to files; `env`
  // entries ("NAME=value") are added to (or override) this process's environment.
  RunResult run(const std::vector<std::string>& args, const std::vector<std::string>& env = {}) const {
    const std::string out_path = capture_ + "/stdout", err_path = capture_ + "/stderr";
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    std::vector<std::string> argv_s{SOFTSHELL_EXE};
    argv_s.insert(argv_s.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& a : argv_s) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_t pid = 0;
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
    const int rc = posix_spawn(&pid, SOFTSHELL_EXE, &actions, nullptr, argv.data(), envp.data());
    posix_spawn_file_actions_destroy(&actions);
    RunResult r;
    if (rc != 0) {
      r.err = std::string("posix_spawn failed: ") + std::strerror(rc);
      return r;
    }
    int ws = 0;
    while (::waitpid(pid, &ws, 0) < 0 && errno == EINTR) {
    }
    r.status = WIFEXITED(ws) ? WEXITSTATUS(ws) : -1;
    r.out = slurp(out_path);
    r.err = slurp(err_path);
    return r;
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
