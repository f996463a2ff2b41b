#include "colmap_bridge/commands/console.h"

#include <csignal>
#include <iostream>

namespace cashash {
namespace colmap {
namespace {

std::atomic<bool> g_stop_requested{false};

extern "C" void HandleInterrupt(int) {
  if (g_stop_requested.exchange(true)) {
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
  }
}

}  // namespace

void PrintHeading(const std::string& title) {
  std::cout << "\n" << std::string(78, '=') << "\n" << title << "\n" << std::string(78, '=') << "\n" << std::endl;
}

void PrintWarning(const std::string& text) { std::cerr << "WARNING: " << text << std::endl; }

StopOnInterrupt::StopOnInterrupt() {
  g_stop_requested = false;
  std::signal(SIGINT, HandleInterrupt);
}

StopOnInterrupt::~StopOnInterrupt() { std::signal(SIGINT, SIG_DFL); }

const std::atomic<bool>* StopOnInterrupt::stop_flag() const { return &g_stop_requested; }

}  // namespace colmap
}  // namespace cashash
