// Wall time of consecutive phases of one thread's work, for the log. A run's
// own summary times only its pipeline; what a user also waits for (opening
// the database, starting the GPU, making the matcher, closing everything
// again) is timed phase by phase with this, so that the slow ones show.
#pragma once

#include <chrono>
#include <string>
#include <utility>
#include <vector>

namespace cashash {

class PhaseClock {
 public:
  struct Phase {
    std::string name;
    double seconds = 0.0;
  };

  PhaseClock() : last_(Clock::now()) {}

  // Ends the phase under way as `name`; the next one starts now. A name
  // given again adds to its phase (a phase may come in several pieces).
  void Mark(const std::string& name) {
    const Clock::time_point now = Clock::now();
    const double seconds = std::chrono::duration<double>(now - last_).count();
    last_ = now;
    for (Phase& phase : phases_) {
      if (phase.name == name) {
        phase.seconds += seconds;
        return;
      }
    }
    phases_.push_back(Phase{name, seconds});
  }

  // Starts the next phase now, leaving the time since the last mark out
  // (it is timed elsewhere, as the pipeline is).
  void Restart() { last_ = Clock::now(); }

  // Phases in the order they were first marked.
  const std::vector<Phase>& phases() const { return phases_; }

  double TotalSeconds() const {
    double total = 0.0;
    for (const Phase& phase : phases_) total += phase.seconds;
    return total;
  }

 private:
  using Clock = std::chrono::steady_clock;
  Clock::time_point last_;
  std::vector<Phase> phases_;
};

}  // namespace cashash
