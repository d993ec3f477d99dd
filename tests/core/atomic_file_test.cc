#include "tofcam/core/atomic_file.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "../scratch_dir.h"
#include "tofcam/core/error.h"

namespace tofcam {
namespace {

namespace fs = std::filesystem;

fs::path TempDir() { return testing::ScratchDir("tofcam_atomic_"); }

TEST(AtomicFileTest, WritesAndReadsBack) {
  const fs::path p = TempDir() / "a.txt";
  WriteFileAtomically(p, "hello");
  EXPECT_EQ(ReadFile(p), "hello");
  WriteFileAtomically(p, "replaced");
  EXPECT_EQ(ReadFile(p), "replaced");
}

TEST(AtomicFileTest, UncommittedWriteLeavesOldFileAndNoTemporary) {
  const fs::path dir = TempDir() / "uncommitted";
  fs::create_directories(dir);
  const fs::path p = dir / "b.txt";
  WriteFileAtomically(p, "old");
  {
    AtomicFile f(p);
    f.Write("half");
    // Destroyed without Commit(), as when an exception unwinds.
  }
  EXPECT_EQ(ReadFile(p), "old");
  int entries = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++entries;
  EXPECT_EQ(entries, 1);
}

// Links at the temporary names (someone else's, in a shared directory such as /tmp, or a
// killed run's leftovers under a reused pid) are never followed and never block the write: the
// file goes to a free name, the link's target keeps its content.
TEST(AtomicFileTest, NeverFollowsALinkAtTheTemporaryName) {
  const fs::path dir = TempDir() / "links";
  fs::create_directories(dir);
  const fs::path victim = dir / "victim.txt";
  WriteFileAtomically(victim, "victim");
  const fs::path p = dir / "c.txt";
  // This process's next temporary names (pid and a counter from 0; few are used before here).
  for (int k = 0; k < 200; ++k) {
    fs::create_symlink(victim,
                       p.string() + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(k));
  }
  WriteFileAtomically(p, "new");
  EXPECT_EQ(ReadFile(p), "new");
  EXPECT_FALSE(fs::is_symlink(p));
  EXPECT_EQ(ReadFile(victim), "victim");
}

TEST(AtomicFileTest, ErrorsNameThePath) {
  try {
    (void)ReadFile("/nonexistent/tofcam/file.yaml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotFound);
    EXPECT_NE(std::string(e.what()).find("/nonexistent/tofcam/file.yaml"), std::string::npos);
  }
  EXPECT_THROW(AtomicFile("/nonexistent/dir/x"), Error);
  const fs::path big = TempDir() / "big.bin";
  WriteFileAtomically(big, std::string(100, 'x'));
  EXPECT_THROW((void)ReadFile(big, 10), Error);
  EXPECT_THROW((void)ReadFile(TempDir()), Error);  // a directory
}

}  // namespace
}  // namespace tofcam
