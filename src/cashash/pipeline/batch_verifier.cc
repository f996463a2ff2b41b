#include "cashash/pipeline/batch_verifier.h"

#include "cashash/base/pair_id.h"
#include "cashash/base/parallel_for.h"

namespace cashash {
namespace {

class CpuBatchVerifier : public BatchVerifier {
 public:
  CpuBatchVerifier(const TwoViewGeometryOptions& options, int num_threads)
      : options_(options), num_threads_(num_threads) {}

  std::string Name() const override { return "cpu"; }

  std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
    std::vector<TwoViewGeometry> geometries(pairs.size());
    ParallelFor(pairs.size(), num_threads_, [&](size_t k) {
      const VerificationPair& pair = pairs[k];
      TwoViewGeometryOptions options = options_;
      options.random_seed = pair.random_seed;
      geometries[k] = EstimateTwoViewGeometry(*pair.camera1, *pair.points1, *pair.camera2, *pair.points2,
                                              *pair.matches, options);
    });
    return geometries;
  }

 private:
  TwoViewGeometryOptions options_;
  int num_threads_;
};

}  // namespace

std::unique_ptr<BatchVerifier> CreateCpuBatchVerifier(const TwoViewGeometryOptions& options, int num_threads) {
  return std::make_unique<CpuBatchVerifier>(options, num_threads);
}

uint64_t PairRandomSeed(uint64_t base_seed, const ImagePair& pair) {
  uint64_t z = base_seed ^ (ImagePairToPairId(pair.first, pair.second) * 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

std::vector<Eigen::Vector2d> KeypointPositions(const Keypoints& keypoints) {
  std::vector<Eigen::Vector2d> points(keypoints.size());
  for (size_t i = 0; i < keypoints.size(); ++i) points[i] = Eigen::Vector2d(keypoints[i].x, keypoints[i].y);
  return points;
}

}  // namespace cashash
