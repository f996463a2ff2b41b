#include "cashash/pipeline/pipeline_trace.h"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <stdexcept>

namespace cashash {

void PipelineTrace::Record(PipelineTraceEvent event) {
  std::lock_guard<std::mutex> lock(mutex_);
  events_.push_back(std::move(event));
}

std::vector<PipelineTraceEvent> PipelineTrace::Events() const {
  std::vector<PipelineTraceEvent> events;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    events = events_;
  }
  std::stable_sort(events.begin(), events.end(),
                   [](const PipelineTraceEvent& a, const PipelineTraceEvent& b) { return a.start < b.start; });
  return events;
}

size_t PipelineTrace::WriteCsv(const std::string& path) const {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("cannot write the pipeline trace to " + path);
  out << "stage,chunk,call,thread,start,end,pairs\n" << std::fixed << std::setprecision(6);
  const std::vector<PipelineTraceEvent> events = Events();
  for (const PipelineTraceEvent& e : events) {
    out << e.stage << ',' << e.chunk << ',' << e.call << ',' << e.thread << ',' << e.start << ',' << e.end << ','
        << e.pairs << '\n';
  }
  out.flush();
  if (!out) throw std::runtime_error("cannot write the pipeline trace to " + path);
  return events.size();
}

}  // namespace cashash
