#include "cashash/pipeline/verification_pairs_file.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <stdexcept>

namespace cashash {
namespace {

constexpr char kMagic[4] = {'C', 'H', 'V', 'P'};
constexpr uint32_t kVersion = 1;
// Guards against reading garbage as a huge count.
constexpr uint32_t kMaxCount = 1u << 26;

class Writer {
 public:
  explicit Writer(const std::string& path) : path_(path), out_(path, std::ios::binary) {
    if (!out_) throw std::runtime_error("cannot write " + path);
  }
  template <typename T>
  void Put(T value) {
    out_.write(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void Finish() {
    out_.flush();
    if (!out_) throw std::runtime_error("error writing " + path_);
  }

 private:
  std::string path_;
  std::ofstream out_;
};

class Reader {
 public:
  explicit Reader(const std::string& path) : path_(path), in_(path, std::ios::binary) {
    if (!in_) throw std::runtime_error("cannot open " + path);
  }
  template <typename T>
  T Get() {
    T value;
    in_.read(reinterpret_cast<char*>(&value), sizeof(T));
    if (!in_) throw std::runtime_error(path_ + ": truncated verification pairs file");
    return value;
  }
  uint32_t Count(const char* what) {
    const uint32_t n = Get<uint32_t>();
    if (n > kMaxCount) throw std::runtime_error(path_ + ": implausible " + std::string(what) + " count");
    return n;
  }

 private:
  std::string path_;
  std::ifstream in_;
};

void PutCamera(Writer& w, const Camera& c) {
  w.Put<int32_t>(c.model_id);
  w.Put<uint64_t>(c.width);
  w.Put<uint64_t>(c.height);
  w.Put<uint8_t>(c.has_prior_focal_length ? 1 : 0);
  w.Put<uint32_t>(static_cast<uint32_t>(c.params.size()));
  for (double p : c.params) w.Put<double>(p);
}

Camera GetCamera(Reader& r) {
  Camera c;
  c.model_id = r.Get<int32_t>();
  c.width = r.Get<uint64_t>();
  c.height = r.Get<uint64_t>();
  c.has_prior_focal_length = r.Get<uint8_t>() != 0;
  c.params.resize(r.Count("camera parameter"));
  for (double& p : c.params) p = r.Get<double>();
  return c;
}

}  // namespace

VerificationPair StoredVerificationPair::View(uint64_t random_seed) const {
  VerificationPair v;
  v.camera1 = &camera1;
  v.camera2 = &camera2;
  v.points1 = &points1;
  v.points2 = &points2;
  v.matches = &matches;
  v.random_seed = random_seed;
  return v;
}

void WriteVerificationPairsFile(const std::string& path, const std::vector<StoredVerificationPair>& pairs) {
  Writer w(path);
  for (char c : kMagic) w.Put<char>(c);
  w.Put<uint32_t>(kVersion);
  w.Put<uint32_t>(static_cast<uint32_t>(pairs.size()));
  for (const StoredVerificationPair& p : pairs) {
    w.Put<uint32_t>(p.pair.first);
    w.Put<uint32_t>(p.pair.second);
    PutCamera(w, p.camera1);
    PutCamera(w, p.camera2);
    w.Put<uint32_t>(static_cast<uint32_t>(p.matches.size()));
    for (const FeatureMatch& m : p.matches) {
      const Eigen::Vector2d& a = p.points1[m.point2D_idx1];
      const Eigen::Vector2d& b = p.points2[m.point2D_idx2];
      w.Put<float>(static_cast<float>(a.x()));
      w.Put<float>(static_cast<float>(a.y()));
      w.Put<float>(static_cast<float>(b.x()));
      w.Put<float>(static_cast<float>(b.y()));
    }
  }
  w.Finish();
}

std::vector<StoredVerificationPair> ReadVerificationPairsFile(const std::string& path) {
  Reader r(path);
  char magic[4];
  for (char& c : magic) c = r.Get<char>();
  if (std::memcmp(magic, kMagic, 4) != 0) throw std::runtime_error(path + ": not a verification pairs file");
  if (r.Get<uint32_t>() != kVersion) throw std::runtime_error(path + ": unsupported version");
  std::vector<StoredVerificationPair> pairs(r.Count("pair"));
  for (StoredVerificationPair& p : pairs) {
    p.pair.first = r.Get<uint32_t>();
    p.pair.second = r.Get<uint32_t>();
    p.camera1 = GetCamera(r);
    p.camera2 = GetCamera(r);
    const uint32_t n = r.Count("match");
    p.points1.resize(n);
    p.points2.resize(n);
    p.matches.resize(n);
    for (uint32_t k = 0; k < n; ++k) {
      const float x1 = r.Get<float>(), y1 = r.Get<float>(), x2 = r.Get<float>(), y2 = r.Get<float>();
      p.points1[k] = Eigen::Vector2d(x1, y1);
      p.points2[k] = Eigen::Vector2d(x2, y2);
      p.matches[k].point2D_idx1 = p.matches[k].point2D_idx2 = k;
    }
  }
  return pairs;
}

}  // namespace cashash
