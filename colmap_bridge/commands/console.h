// What every cashash command prints and how it stops: COLMAP-style headings,
// "WARNING: " lines on stderr, and Ctrl-C.
#pragma once

#include <atomic>
#include <string>

namespace cashash {
namespace colmap {

// A line of '=' above and below the title, as COLMAP prints its headings.
void PrintHeading(const std::string& title);

// "WARNING: text" on stderr.
void PrintWarning(const std::string& text);

// While it lives, the first Ctrl-C sets stop_flag(): the run finishes and
// commits the chunks in flight, then returns. A second one ends the process
// at once (the database stays valid: every chunk is one transaction). One
// at a time per process.
class StopOnInterrupt {
 public:
  StopOnInterrupt();
  ~StopOnInterrupt();
  StopOnInterrupt(const StopOnInterrupt&) = delete;
  StopOnInterrupt& operator=(const StopOnInterrupt&) = delete;

  const std::atomic<bool>* stop_flag() const;
};

}  // namespace colmap
}  // namespace cashash
