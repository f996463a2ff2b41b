#include "cashash_cuda/matching/guided_matching.h"

#include <utility>

#include "cashash_cuda/geometry/two_view_geometry.h"

namespace cashash {
namespace cuda {
namespace {

class GpuFundamentalEstimator : public BatchFundamentalEstimator {
 public:
  GpuFundamentalEstimator(const TwoViewGeometryOptions& options, int gpu_index,
                          std::shared_ptr<GpuResources> resources)
      : ransac_(options, gpu_index, std::move(resources)) {}
  std::string Name() const override { return "gpu"; }
  std::vector<TwoViewModelEstimate> Estimate(const std::vector<const TwoViewPoints*>& pairs,
                                             const std::vector<uint64_t>& seeds) override {
    std::vector<TwoViewModelEstimate> F, H;
    ransac_.Estimate(pairs, seeds, &F, &H);
    return F;
  }

 private:
  GpuTwoViewRansac ransac_;
};

}  // namespace

std::unique_ptr<BatchFundamentalEstimator> CreateGpuFundamentalEstimator(const TwoViewGeometryOptions& options,
                                                                         int gpu_index,
                                                                         std::shared_ptr<GpuResources> resources) {
  return std::make_unique<GpuFundamentalEstimator>(options, gpu_index, std::move(resources));
}

}  // namespace cuda
}  // namespace cashash
