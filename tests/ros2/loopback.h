#pragma once
// Helpers of the two-process ROS 2 tests: a DDS domain of our own, Cyclone kept on loopback, and
// child processes with a bounded wait (a hung child is killed and reported, never waited on
// forever).
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace tofcam::ros2_test {

/// Holds an flock on /tmp/tofcam-dds-domain-<id>.lock for the process's lifetime, so parallel
/// test runs on this machine never share a domain. Domains 100..229 (0 is ROS's default).
inline int ClaimDomain() {
  static int domain = [] {
    std::mt19937 rng(static_cast<unsigned>(getpid()));
    const int start = static_cast<int>(rng() % 130);
    for (int k = 0; k < 130; ++k) {
      const int d = 100 + (start + k) % 130;
      const std::string path = "/tmp/tofcam-dds-domain-" + std::to_string(d) + ".lock";
      const int fd = open(path.c_str(), O_CREAT | O_RDWR, 0666);
      if (fd >= 0 && flock(fd, LOCK_EX | LOCK_NB) == 0) return d;  // fd stays open: lock held
      if (fd >= 0) close(fd);
    }
    return -1;
  }();
  return domain;
}

/// Cyclone DDS on the loopback interface only, unicast discovery to 127.0.0.1 (no multicast),
/// set for this process and inherited by its children.
inline void UseLoopbackOnly() {
  setenv("CYCLONEDDS_URI",
         "<CycloneDDS><Domain Id=\"any\"><General><Interfaces><NetworkInterface name=\"lo\"/>"
         "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
         "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30"
         "</MaxAutoParticipantIndex><Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>"
         "</Domain></CycloneDDS>",
         1);
}

struct Child {
  pid_t pid = -1;
  std::string log;  // stdout + stderr
};

inline Child Spawn(const std::vector<std::string>& args, const std::string& log) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_adddup2(&actions, 1, 2);
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  Child c;
  c.log = log;
  if (posix_spawn(&c.pid, argv[0], &actions, nullptr, argv.data(), environ) != 0) c.pid = -1;
  posix_spawn_file_actions_destroy(&actions);
  return c;
}

/// Exit status of the child, or -1 when it had to be killed after `limit_s` (a safety bound,
/// not a timing assertion).
inline int Wait(Child& c, double limit_s = 120.0) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(limit_s);
  int status = 0;
  while (true) {
    const pid_t r = waitpid(c.pid, &status, WNOHANG);
    if (r == c.pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
    if (r < 0) return -2;
    if (std::chrono::steady_clock::now() > deadline) {
      kill(c.pid, SIGKILL);
      waitpid(c.pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

inline std::string ReadText(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// A fresh scratch directory under the system temp dir.
inline std::filesystem::path ScratchDir(const std::string& name) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() /
                                    ("tofcam-ros2-" + name + "-" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

}  // namespace tofcam::ros2_test
