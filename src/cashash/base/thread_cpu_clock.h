// CPU time of the calling thread. A stage's wall time on a busy machine
// also holds the time its thread waited for a core or for the disk; its CPU
// time is what the stage itself cost, so a report gives both.
#pragma once

#include <time.h>

namespace cashash {

// Seconds of CPU the calling thread has used since it started; 0 where the
// system has no per-thread CPU clock.
inline double ThreadCpuSeconds() {
#ifdef CLOCK_THREAD_CPUTIME_ID
  timespec now{};
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &now) != 0) return 0.0;
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
#else
  return 0.0;
#endif
}

}  // namespace cashash
