// What each stage of one pipeline run did and when, chunk by chunk. The
// summary's stage times say how long each stage was busy and how long it
// waited; they cannot say which chunk's work overlapped which, and so not
// what set the run's length (a slow chunk's verification, the tail after
// matching, a writer that fell behind). The trace records every stage's
// interval per chunk so that the critical path can be read off a run
// (scripts/bench/pipeline_trace_summary.py).
#pragma once

#include <cstddef>
#include <mutex>
#include <string>
#include <vector>

namespace cashash {

struct PipelineTraceEvent {
  // "load" (features and hashing), "match", "rematch" (what the matcher
  // deferred), "verify" (one verifier call, recorded once per chunk of the
  // call), "write".
  std::string stage;
  size_t chunk = 0;  // index in the run's chunks
  size_t call = 0;   // the verifier call, numbered from 1 ("verify" only)
  int thread = 0;    // 0 the matching thread, 1.. the verification threads, -1 the writer
  double start = 0;  // seconds since the run started
  double end = 0;
  size_t pairs = 0;  // the chunk's pairs
};

class PipelineTrace {
 public:
  // From any thread.
  void Record(PipelineTraceEvent event);
  // Ordered by start time.
  std::vector<PipelineTraceEvent> Events() const;
  // One header line, then an event per line:
  // stage,chunk,call,thread,start,end,pairs. Returns the number of events;
  // throws std::runtime_error naming the path when it cannot be written.
  size_t WriteCsv(const std::string& path) const;

 private:
  mutable std::mutex mutex_;
  std::vector<PipelineTraceEvent> events_;
};

}  // namespace cashash
