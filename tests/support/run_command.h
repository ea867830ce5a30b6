// Test support: runs a shell command, capturing stdout and stderr together
// (run_command) or apart (run_command_split); its exit status (-1 if it did
// not exit normally).
#pragma once

#include <sys/wait.h>

#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

namespace terrane::testing_support {

inline int run_command(const std::string& cmd, std::string* out) {
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) return -1;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out->append(buf, n);
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// The same with stdout in *out and stderr in *err.
inline int run_command_split(const std::string& cmd, std::string* out, std::string* err) {
  char path[] = "/tmp/terrane-stderr-XXXXXX";
  const int fd = mkstemp(path);
  if (fd < 0) return -1;
  ::close(fd);
  FILE* p = popen((cmd + " 2>" + path).c_str(), "r");
  if (p == nullptr) return ::unlink(path), -1;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p)) > 0) out->append(buf, n);
  const int status = pclose(p);
  std::ifstream in(path);
  std::ostringstream text;
  text << in.rdbuf();
  *err += text.str();
  ::unlink(path);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace terrane::testing_support
