#include "colmap_bridge/api/process_clock.h"

#include <chrono>

namespace cashash {
namespace colmap {
namespace {

// Initialised before main(), with the other statics of the executable.
const std::chrono::steady_clock::time_point kProcessStart = std::chrono::steady_clock::now();

}  // namespace

double SecondsSinceProcessStart() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - kProcessStart).count();
}

}  // namespace colmap
}  // namespace cashash
