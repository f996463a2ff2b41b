// Configuration travels in options and config structs, never in the
// process environment: the library sources read and write no environment
// variable, and a run leaves the environment as it found it (setenv while
// another thread reads the environment is undefined behaviour in POSIX,
// and a run has threads of its own).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace cashash {
namespace {

namespace fs = std::filesystem;

TEST(LibraryEnvironment, NoLibrarySourceReadsOrWritesTheEnvironment) {
  const fs::path root = CASHASH_SOURCE_DIR;
  const std::regex call(R"(\b(getenv|secure_getenv|setenv|unsetenv|putenv|clearenv)\s*\(|\benviron\b)");
  std::vector<std::string> found;
  size_t files = 0;
  for (const char* folder : {"src", "cuda", "colmap_bridge", "distributed", "python"}) {
    if (!fs::exists(root / folder)) continue;
    for (const fs::directory_entry& entry : fs::recursive_directory_iterator(root / folder)) {
      const std::string extension = entry.path().extension().string();
      // Tests (python/tests) may set up their own environment.
      if (entry.path().string().find("/tests/") != std::string::npos) continue;
      if (!entry.is_regular_file() ||
          (extension != ".h" && extension != ".cc" && extension != ".cu" && extension != ".cuh" &&
           extension != ".py")) {
        continue;
      }
      ++files;
      std::ifstream in(entry.path());
      std::string line;
      for (int number = 1; std::getline(in, line); ++number) {
        if (std::regex_search(line, call)) {
          found.push_back(fs::relative(entry.path(), root).string() + ":" + std::to_string(number) + ": " + line);
        }
      }
    }
  }
  EXPECT_GT(files, 100u) << "the source folders were not found under " << root;
  std::ostringstream list;
  for (const std::string& hit : found) list << "\n  " << hit;
  EXPECT_TRUE(found.empty()) << "environment access in library code:" << list.str();
}

}  // namespace
}  // namespace cashash
