#include "distributed/mpi_result_codec.h"

#include <cstring>
#include <stdexcept>

namespace cashash {
namespace distributed {
namespace {

class Writer {
 public:
  template <typename T>
  void Put(const T& value) {
    const size_t at = bytes_.size();
    bytes_.resize(at + sizeof(T));
    std::memcpy(bytes_.data() + at, &value, sizeof(T));
  }
  void PutMatches(const FeatureMatches& matches) {
    Put<uint64_t>(matches.size());
    for (const FeatureMatch& m : matches) {
      Put(m.point2D_idx1);
      Put(m.point2D_idx2);
    }
  }
  template <typename Matrix>
  void PutMatrix(const Matrix& matrix) {
    for (int i = 0; i < matrix.size(); ++i) Put<double>(matrix.data()[i]);
  }
  void PutString(const std::string& text) {
    Put<uint64_t>(text.size());
    bytes_.insert(bytes_.end(), text.begin(), text.end());
  }
  size_t size() const { return bytes_.size(); }
  std::vector<uint8_t> Take() { return std::move(bytes_); }

 private:
  std::vector<uint8_t> bytes_;
};

class Reader {
 public:
  explicit Reader(const std::vector<uint8_t>& bytes) : bytes_(bytes) {}
  template <typename T>
  T Get() {
    Need(sizeof(T));
    T value;
    std::memcpy(&value, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  FeatureMatches GetMatches() {
    const uint64_t count = Get<uint64_t>();
    Need(count * 2 * sizeof(point2D_t));
    FeatureMatches matches(count);
    for (FeatureMatch& m : matches) {
      m.point2D_idx1 = Get<point2D_t>();
      m.point2D_idx2 = Get<point2D_t>();
    }
    return matches;
  }
  template <typename Matrix>
  void GetMatrix(Matrix* matrix) {
    for (int i = 0; i < matrix->size(); ++i) matrix->data()[i] = Get<double>();
  }
  std::string GetString() {
    const uint64_t size = Get<uint64_t>();
    Need(size);
    std::string text(bytes_.begin() + at_, bytes_.begin() + at_ + size);
    at_ += size;
    return text;
  }
  void ExpectEnd() const {
    if (at_ != bytes_.size()) throw std::runtime_error("MPI message: " + std::to_string(bytes_.size() - at_) +
                                                       " unexpected bytes at the end");
  }

 private:
  void Need(uint64_t count) const {
    if (count > bytes_.size() - at_) throw std::runtime_error("MPI message is truncated");
  }
  const std::vector<uint8_t>& bytes_;
  size_t at_ = 0;
};

void PutResult(Writer* w, const PairResult& r) {
  w->Put(r.pair.first);
  w->Put(r.pair.second);
  w->PutMatches(r.matches);
  w->Put<int32_t>(r.geometry.config);
  w->PutMatrix(r.geometry.F);
  w->PutMatrix(r.geometry.E);
  w->PutMatrix(r.geometry.H);
  w->PutMatrix(r.geometry.qvec);
  w->PutMatrix(r.geometry.tvec);
  w->PutMatches(r.geometry.inlier_matches);
}

PairResult GetResult(Reader* r) {
  PairResult result;
  result.pair.first = r->Get<image_t>();
  result.pair.second = r->Get<image_t>();
  result.matches = r->GetMatches();
  result.geometry.config = r->Get<int32_t>();
  r->GetMatrix(&result.geometry.F);
  r->GetMatrix(&result.geometry.E);
  r->GetMatrix(&result.geometry.H);
  r->GetMatrix(&result.geometry.qvec);
  r->GetMatrix(&result.geometry.tvec);
  result.geometry.inlier_matches = r->GetMatches();
  return result;
}

size_t EncodedSize(const PairResult& r) {
  return 2 * sizeof(image_t) + 2 * sizeof(uint64_t) + (r.matches.size() + r.geometry.inlier_matches.size()) * 8 +
         sizeof(int32_t) + (27 + 4 + 3) * sizeof(double);
}

void PutHeader(Writer* w, int block_i, int block_j, int num_blocks, bool last_part, uint64_t count) {
  w->Put<int32_t>(block_i);
  w->Put<int32_t>(block_j);
  w->Put<int32_t>(num_blocks);
  w->Put<uint8_t>(last_part ? 1 : 0);
  w->Put<uint64_t>(count);
}

}  // namespace

std::vector<uint8_t> EncodeChunkResults(const ChunkResultsMessage& message) {
  Writer w;
  PutHeader(&w, message.block_i, message.block_j, message.num_blocks, message.last_part, message.results.size());
  for (const PairResult& r : message.results) PutResult(&w, r);
  return w.Take();
}

ChunkResultsMessage DecodeChunkResults(const std::vector<uint8_t>& bytes) {
  Reader r(bytes);
  ChunkResultsMessage message;
  message.block_i = r.Get<int32_t>();
  message.block_j = r.Get<int32_t>();
  message.num_blocks = r.Get<int32_t>();
  message.last_part = r.Get<uint8_t>() != 0;
  const uint64_t count = r.Get<uint64_t>();
  if (count > bytes.size()) throw std::runtime_error("MPI message: impossible result count");
  message.results.reserve(count);
  for (uint64_t k = 0; k < count; ++k) message.results.push_back(GetResult(&r));
  r.ExpectEnd();
  return message;
}

std::vector<std::vector<uint8_t>> EncodeChunkInParts(const PairChunk& chunk, const std::vector<PairResult>& results,
                                                     size_t max_bytes) {
  std::vector<std::vector<uint8_t>> parts;
  size_t begin = 0;
  do {
    size_t end = begin, bytes = 0;
    while (end < results.size() && (end == begin || bytes + EncodedSize(results[end]) <= max_bytes)) {
      bytes += EncodedSize(results[end]);
      ++end;
    }
    Writer w;
    PutHeader(&w, chunk.block_i, chunk.block_j, chunk.num_blocks, end == results.size(), end - begin);
    for (size_t k = begin; k < end; ++k) PutResult(&w, results[k]);
    parts.push_back(w.Take());
    begin = end;
  } while (begin < results.size());
  return parts;
}

std::vector<uint8_t> EncodeRankReport(const RankReport& report) {
  Writer w;
  const PipelineStats& s = report.stats;
  for (size_t value :
       {s.pairs_total, s.pairs_done, s.raw_matches, s.verified_pairs, s.inlier_matches, s.verification_calls}) {
    w.Put<uint64_t>(value);
  }
  for (double value : {s.seconds_total, s.seconds_loading, s.seconds_hashing, s.seconds_matching,
                       s.seconds_verification, s.seconds_writing, s.seconds_writing_cpu}) {
    w.Put<double>(value);
  }
  w.Put<uint8_t>(s.stopped ? 1 : 0);
  w.PutString(report.matcher_name);
  return w.Take();
}

RankReport DecodeRankReport(const std::vector<uint8_t>& bytes) {
  Reader r(bytes);
  RankReport report;
  PipelineStats& s = report.stats;
  for (size_t* value : {&s.pairs_total, &s.pairs_done, &s.raw_matches, &s.verified_pairs, &s.inlier_matches,
                        &s.verification_calls}) {
    *value = r.Get<uint64_t>();
  }
  for (double* value : {&s.seconds_total, &s.seconds_loading, &s.seconds_hashing, &s.seconds_matching,
                        &s.seconds_verification, &s.seconds_writing, &s.seconds_writing_cpu}) {
    *value = r.Get<double>();
  }
  s.stopped = r.Get<uint8_t>() != 0;
  report.matcher_name = r.GetString();
  r.ExpectEnd();
  return report;
}

}  // namespace distributed
}  // namespace cashash
