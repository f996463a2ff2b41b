// Host side of the GPU verification: packs a batch of pairs' normalised
// correspondences (and calibrated pairs' normalised camera coordinates),
// runs the F/H and E kernels, and turns their outputs into the estimates the
// CPU path's decision reads.
#include "cashash_cuda/geometry/two_view_geometry.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <stdexcept>
#include <string>

#include "cashash/base/device_memory_error.h"
#include "cashash/geometry/launch_order.h"
#include "cashash/geometry/random_sampler.h"
#include "cashash/geometry/ransac.h"
#include "cashash/base/parallel_for.h"
#include "cashash_cuda/matchers/gpu_feature_matcher.h"
#include "cashash_cuda/utils/device_memory.cuh"
#include "cashash_cuda/geometry/ransac.cuh"
#include "cashash_cuda/utils/cuda_check.cuh"
#include "cashash_cuda/utils/stream_priority.cuh"

namespace cashash {
namespace cuda {
namespace {

// Grow buffers geometrically so that chunk after chunk reuses them.
void Reserve(GpuResources* owner, DeviceBuffer* buffer, size_t bytes, const char* what) {
  if (buffer->bytes() >= bytes) return;
  buffer->Allocate(owner, bytes + bytes / 2, what);
}

void Reserve(GpuResources* owner, PinnedBuffer* buffer, size_t bytes, const char* what) {
  if (buffer->bytes() >= bytes) return;
  buffer->Allocate(owner, bytes + bytes / 2, what);
}

Eigen::Matrix3d FromRowMajor(const double* v) {
  Eigen::Matrix3d m;
  m << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
  return m;
}

// One batch's slots. F's pairs take slots [0, num_pairs), H's the same pairs
// in [num_pairs, 2 num_pairs), over one shared point array, largest pairs
// first (LargestFirst, launch_order.h: blocks start roughly in order; big
// ones last would leave a long tail): slot j holds pair order[j]. E's pairs
// (their own points, in normalised camera coordinates) follow, again largest
// first: slot 2 num_pairs + j holds pair order_E[j]. E's points follow F/H's
// in the point array (offsets from the array's start); its masks follow F's
// and H's.
struct RansacBatchLayout {
  size_t num_pairs = 0;
  std::vector<size_t> order;
  std::vector<size_t> order_E;
  std::vector<RansacPairInput> inputs;  // one per slot
  size_t total = 0;                     // F/H points
  size_t total_E = 0;                   // E points
  int max_count = 0;                    // most points of an F/H pair
  int max_count_E = 0;                  // most points of an E pair

  size_t num_E() const { return order_E.size(); }
  size_t all_points() const { return total + total_E; }
  size_t mask_bytes() const { return 2 * total + total_E; }
};

RansacBatchLayout LayOutBatch(const std::vector<const TwoViewPoints*>& pairs, const std::vector<uint64_t>& seeds,
                              const std::vector<const EssentialPoints*>& essential,
                              const TwoViewGeometryOptions& options) {
  RansacBatchLayout layout;
  const size_t num_pairs = pairs.size();
  layout.num_pairs = num_pairs;
  std::vector<size_t> matches_per_pair(num_pairs);
  for (size_t k = 0; k < num_pairs; ++k) matches_per_pair[k] = pairs[k]->normalized.size();
  layout.order = LargestFirst(matches_per_pair);
  const std::vector<size_t>& order = layout.order;
  std::vector<int> slot_E;  // F/H slot of each E pair
  for (size_t j = 0; j < essential.size(); ++j) {
    if (essential[order[j]] == nullptr) continue;
    layout.order_E.push_back(order[j]);
    slot_E.push_back(static_cast<int>(j));
  }
  const size_t num_E = layout.num_E();
  std::vector<RansacPairInput>& inputs = layout.inputs;
  inputs.resize(2 * num_pairs + num_E);
  for (size_t j = 0; j < num_pairs; ++j) {
    const size_t k = order[j];
    const size_t n = pairs[k]->normalized.size();
    if (layout.total + n > static_cast<size_t>(INT32_MAX)) {
      throw std::runtime_error("GPU verification batch too large");
    }
    RansacPairInput& f = inputs[j];
    f.offset = static_cast<int>(layout.total);
    f.count = static_cast<int>(n);
    f.squared_threshold = static_cast<float>(NormalizedSquaredThreshold(*pairs[k], options));
    f.seed = DeriveSeed(seeds[k], kSeedF);
    RansacPairInput& h = inputs[num_pairs + j];
    h = f;
    h.seed = DeriveSeed(seeds[k], kSeedH);
    layout.total += n;
    layout.max_count = std::max(layout.max_count, f.count);
  }
  for (size_t j = 0; j < num_E; ++j) {
    const EssentialPoints& e = *essential[layout.order_E[j]];
    const size_t n = e.world.size();
    if (layout.total + layout.total_E + n > static_cast<size_t>(INT32_MAX)) {
      throw std::runtime_error("GPU verification batch too large");
    }
    RansacPairInput& in = inputs[2 * num_pairs + j];
    in.offset = static_cast<int>(layout.total + layout.total_E);
    in.count = static_cast<int>(n);
    // As LoRansac compares: float residuals against float(max_error^2).
    in.squared_threshold = static_cast<float>(e.max_error * e.max_error);
    in.seed = DeriveSeed(seeds[layout.order_E[j]], kSeedE);
    in.reference = slot_E[j];
    layout.total_E += n;
    layout.max_count_E = std::max(layout.max_count_E, in.count);
  }
  return layout;
}

// Packing and unpacking run on all cores: at tens of thousands of pairs per
// second they would otherwise cost as much as the kernels.
void PackPoints(const RansacBatchLayout& layout, const std::vector<const TwoViewPoints*>& pairs,
                const std::vector<const EssentialPoints*>& essential, float4* host_points) {
  const size_t num_pairs = layout.num_pairs;
  ParallelFor(num_pairs + layout.num_E(), -1, [&](size_t j) {
    const PointPairs& p =
        j < num_pairs ? pairs[layout.order[j]]->normalized : essential[layout.order_E[j - num_pairs]]->world;
    float4* out = host_points + layout.inputs[j < num_pairs ? j : num_pairs + j].offset;
    for (size_t i = 0; i < p.size(); ++i) out[i] = make_float4(p.fx1[i], p.fy1[i], p.fx2[i], p.fy2[i]);
  });
}

// The kernels' launches over the device buffers of one batch.
struct RansacLaunches {
  RansacLaunch F, H, E;
  bool E_after_F_and_H = false;
};

RansacLaunches MakeLaunches(const RansacBatchLayout& layout, const TwoViewGeometryOptions& options,
                            float4* points, RansacPairInput* inputs, RansacPairOutput* outputs, uint8_t* masks) {
  const size_t num_pairs = layout.num_pairs;
  RansacOptions ransac;
  ransac.confidence = options.confidence;
  ransac.min_num_trials = options.min_num_trials;
  ransac.max_num_trials = options.max_num_trials;
  ransac.min_inlier_ratio = options.min_inlier_ratio;
  RansacLaunches launches;
  RansacLaunch& F_launch = launches.F;
  F_launch.points = points;
  F_launch.num_pairs = static_cast<int>(num_pairs);
  F_launch.min_trials = options.min_num_trials;
  F_launch.confidence = options.confidence;
  F_launch.trials_multiplier = ransac.num_trials_multiplier;
  F_launch.shared_points = std::min(layout.max_count, kRansacMaxSharedPoints);
  F_launch.early_exit = TwoViewEarlyExitOptions(options);
  F_launch.sprt_max_risk = TwoViewSprtMaxRisk(options);
  RansacLaunch& H_launch = launches.H;
  RansacLaunch& E_launch = launches.E;
  H_launch = F_launch;
  E_launch = F_launch;
  F_launch.pairs = inputs;
  F_launch.outputs = outputs;
  F_launch.masks = masks;
  F_launch.max_trials = RansacMaxTrials(ransac, 7);
  H_launch.pairs = inputs + num_pairs;
  H_launch.outputs = outputs + num_pairs;
  H_launch.masks = masks + layout.total;
  H_launch.max_trials = RansacMaxTrials(ransac, 4);
  if (options.early_exit) {
    // H only matters above a share of F's inliers: it runs after F and
    // stops once no model that could change the decision exists.
    H_launch.relevance = F_launch.outputs;
    H_launch.relevance_ratio = TwoViewRelevantHomographyRatio(options);
    H_launch.relevance_min_inliers = std::max(0, options.min_num_inliers);
  }
  // E's masks sit at 2 total + (offset - total): the kernel indexes masks by
  // the pair's point offset, so its base is shifted back by `total`.
  E_launch.num_pairs = static_cast<int>(layout.num_E());
  E_launch.pairs = inputs + 2 * num_pairs;
  E_launch.outputs = outputs + 2 * num_pairs;
  E_launch.masks = masks + layout.total;
  E_launch.max_trials = RansacMaxTrials(ransac, 5);
  E_launch.shared_points = std::min(layout.max_count_E, kEssentialMaxSharedPoints);
  launches.E_after_F_and_H = options.early_exit;
  if (launches.E_after_F_and_H) {
    // E reads F's and H's counts and stops once it cannot change the
    // decision (TwoViewEssentialSettledInliers): many of its trials were on
    // pairs whose configuration was settled long before the cap.
    E_launch.reference_F = F_launch.outputs;
    E_launch.reference_H = H_launch.outputs;
    E_launch.reference_E_F_ratio = options.min_E_F_inlier_ratio;
    E_launch.reference_max_H_ratio = options.max_H_inlier_ratio;
    E_launch.reference_min_inliers = TwoViewEssentialSettledMinInliers(options);
  }
  return launches;
}

// One model's estimate from the kernel's output; the model as the kernel
// left it (row-major, normalised coordinates).
void ReadEstimate(const RansacPairOutput& out, const uint8_t* mask, int count, TwoViewModelEstimate* e) {
  e->success = out.success != 0;
  e->num_inliers = e->success ? out.num_inliers : 0;
  e->num_trials = out.num_trials;
  e->early_exit = out.early_exit != 0;
  if (e->success) {
    e->model = FromRowMajor(out.model);
    e->inlier_mask.assign(mask, mask + count);
  }
}

void UnpackEstimates(const RansacBatchLayout& layout, const std::vector<const TwoViewPoints*>& pairs,
                     const RansacPairOutput* outputs, const uint8_t* masks, std::vector<TwoViewModelEstimate>* F,
                     std::vector<TwoViewModelEstimate>* H, std::vector<TwoViewModelEstimate>* E) {
  const size_t num_pairs = layout.num_pairs;
  const std::vector<RansacPairInput>& inputs = layout.inputs;
  ParallelFor(num_pairs + layout.num_E(), -1, [&](size_t j) {
    if (j >= num_pairs) {
      // Normalised camera coordinates, as the CPU's.
      const size_t slot = 2 * num_pairs + (j - num_pairs);
      ReadEstimate(outputs[slot], masks + layout.total + inputs[slot].offset, inputs[slot].count,
                   &(*E)[layout.order_E[j - num_pairs]]);
      return;
    }
    const size_t k = layout.order[j];
    for (int model = 0; model < 2; ++model) {
      TwoViewModelEstimate& e = model == 0 ? (*F)[k] : (*H)[k];
      ReadEstimate(outputs[model * num_pairs + j], masks + model * layout.total + inputs[j].offset,
                   inputs[j].count, &e);
      if (!e.success) continue;
      e.model = model == 0 ? FundamentalToPixels(e.model, pairs[k]->norm)
                           : HomographyToPixels(e.model, pairs[k]->norm);
    }
  });
}

void AddBatchStats(const RansacBatchLayout& layout, const RansacPairOutput* outputs, GpuRansacStats* stats) {
  const size_t num_pairs = layout.num_pairs;
  for (size_t j = 0; j < 2 * num_pairs; ++j) {
    (j < num_pairs ? stats->trials_F : stats->trials_H) += outputs[j].num_trials;
    (j < num_pairs ? stats->local_refits_F : stats->local_refits_H) += outputs[j].num_local_refits;
    (j < num_pairs ? stats->early_exits_F : stats->early_exits_H) += outputs[j].early_exit;
  }
  for (size_t j = 0; j < layout.num_E(); ++j) {
    stats->trials_E += outputs[2 * num_pairs + j].num_trials;
    stats->local_refits_E += outputs[2 * num_pairs + j].num_local_refits;
    stats->early_exits_E += outputs[2 * num_pairs + j].early_exit;
  }
  stats->pairs += num_pairs;
  stats->pairs_E += layout.num_E();
  stats->points += layout.total;
}

}  // namespace

struct GpuTwoViewRansac::Impl {
  std::shared_ptr<GpuResources> resources;  // first in, last out
  TwoViewGeometryOptions options;
  int device = 0;
  cudaStream_t stream = nullptr, stream_E = nullptr;
  cudaEvent_t start = nullptr, stop = nullptr, uploaded = nullptr, done_E = nullptr;
  DeviceBuffer points, inputs, outputs, masks;
  PinnedBuffer host_points, host_outputs, host_masks;
  GpuRansacStats stats;

  void ReserveBuffers(const RansacBatchLayout& layout);
  void Launch(const RansacLaunches& launches, size_t num_E);
};

void GpuTwoViewRansac::Impl::ReserveBuffers(const RansacBatchLayout& layout) {
  GpuResources* owner = resources.get();
  Reserve(owner, &points, layout.all_points() * sizeof(float4), "RANSAC points");
  Reserve(owner, &inputs, layout.inputs.size() * sizeof(RansacPairInput), "RANSAC pair inputs");
  Reserve(owner, &outputs, layout.inputs.size() * sizeof(RansacPairOutput), "RANSAC pair outputs");
  Reserve(owner, &masks, layout.mask_bytes(), "RANSAC inlier masks");
}

// F and H on `stream`; E after them on the same stream where it reads their
// counts, else on its own stream beside them.
void GpuTwoViewRansac::Impl::Launch(const RansacLaunches& launches, size_t num_E) {
  if (!launches.E_after_F_and_H && num_E > 0) {
    // COLMAP's loop: E (the longest) starts first on its own stream; F and
    // H run beside it.
    CUDA_CHECK(cudaEventRecord(uploaded, stream));
    CUDA_CHECK(cudaStreamWaitEvent(stream_E, uploaded, 0));
    LaunchEssentialRansac(launches.E, stream_E);
    CUDA_CHECK(cudaEventRecord(done_E, stream_E));
  }
  if (launches.H.relevance != nullptr) {
    RansacLaunch no_H = launches.H, no_F = launches.F;
    no_H.num_pairs = 0;
    no_F.num_pairs = 0;
    LaunchTwoViewRansac(launches.F, no_H, stream);
    LaunchTwoViewRansac(no_F, launches.H, stream);
  } else {
    LaunchTwoViewRansac(launches.F, launches.H, stream);
  }
  if (launches.E_after_F_and_H) {
    if (num_E > 0) LaunchEssentialRansac(launches.E, stream);
  } else if (num_E > 0) {
    CUDA_CHECK(cudaStreamWaitEvent(stream, done_E, 0));
  }
}

GpuTwoViewRansac::GpuTwoViewRansac(const TwoViewGeometryOptions& options, int gpu_index,
                                   std::shared_ptr<GpuResources> resources)
    : impl_(std::make_unique<Impl>()) {
  std::string reason;
  if (!CudaDeviceUsable(gpu_index, &reason)) throw std::runtime_error(reason);
  impl_->resources = resources ? std::move(resources) : std::make_shared<GpuResources>(gpu_index, 0);
  impl_->options = options;
  impl_->device = gpu_index;
  CUDA_CHECK(cudaSetDevice(gpu_index));
  impl_->stream = CreateStageStream(StreamRole::kVerification);
  impl_->stream_E = CreateStageStream(StreamRole::kVerification);
  CUDA_CHECK(cudaEventCreate(&impl_->start));
  CUDA_CHECK(cudaEventCreate(&impl_->stop));
  CUDA_CHECK(cudaEventCreateWithFlags(&impl_->uploaded, cudaEventDisableTiming));
  CUDA_CHECK(cudaEventCreateWithFlags(&impl_->done_E, cudaEventDisableTiming));
}

GpuTwoViewRansac::~GpuTwoViewRansac() {
  cudaSetDevice(impl_->device);
  for (cudaEvent_t event : {impl_->start, impl_->stop, impl_->uploaded, impl_->done_E}) {
    if (event != nullptr) cudaEventDestroy(event);
  }
  if (impl_->stream_E != nullptr) cudaStreamDestroy(impl_->stream_E);
  if (impl_->stream != nullptr) cudaStreamDestroy(impl_->stream);
}

const GpuRansacStats& GpuTwoViewRansac::stats() const { return impl_->stats; }

void GpuTwoViewRansac::Estimate(const std::vector<const TwoViewPoints*>& pairs, const std::vector<uint64_t>& seeds,
                                std::vector<TwoViewModelEstimate>* F, std::vector<TwoViewModelEstimate>* H,
                                const std::function<void()>& while_running) {
  Estimate(pairs, seeds, {}, F, H, nullptr, while_running);
}

// One batch: its slot layout, the packing, the F/H/E launches and the
// unpacking, around async copies and events that must run in this order.
void GpuTwoViewRansac::Estimate(const std::vector<const TwoViewPoints*>& pairs, const std::vector<uint64_t>& seeds,
                                const std::vector<const EssentialPoints*>& essential,
                                std::vector<TwoViewModelEstimate>* F, std::vector<TwoViewModelEstimate>* H,
                                std::vector<TwoViewModelEstimate>* E, const std::function<void()>& while_running) {
  if (seeds.size() != pairs.size()) throw std::invalid_argument("GpuTwoViewRansac::Estimate: one seed per pair");
  if (!essential.empty() && (essential.size() != pairs.size() || E == nullptr)) {
    throw std::invalid_argument("GpuTwoViewRansac::Estimate: E needs one entry per pair and an output");
  }
  const auto t0 = std::chrono::steady_clock::now();
  Impl& d = *impl_;
  CUDA_CHECK(cudaSetDevice(d.device));
  const size_t num_pairs = pairs.size();
  F->assign(num_pairs, TwoViewModelEstimate());
  H->assign(num_pairs, TwoViewModelEstimate());
  if (E != nullptr) E->assign(num_pairs, TwoViewModelEstimate());
  if (num_pairs == 0) {
    if (while_running) while_running();
    return;
  }

  const RansacBatchLayout layout = LayOutBatch(pairs, seeds, essential, d.options);
  const size_t all_points = layout.all_points();
  GpuResources* owner = d.resources.get();
  Reserve(owner, &d.host_points, all_points * sizeof(float4), "RANSAC host staging");
  float4* host_points = d.host_points.host<float4>();
  PackPoints(layout, pairs, essential, host_points);
  d.ReserveBuffers(layout);

  CUDA_CHECK(cudaEventRecord(d.start, d.stream));
  CUDA_CHECK(cudaMemcpyAsync(d.points.as<float4>(), host_points, all_points * sizeof(float4),
                             cudaMemcpyHostToDevice, d.stream));
  CUDA_CHECK(cudaMemcpyAsync(d.inputs.as<RansacPairInput>(), layout.inputs.data(),
                             layout.inputs.size() * sizeof(RansacPairInput), cudaMemcpyHostToDevice, d.stream));
  d.Launch(MakeLaunches(layout, d.options, d.points.as<float4>(), d.inputs.as<RansacPairInput>(),
                        d.outputs.as<RansacPairOutput>(), d.masks.as<uint8_t>()),
           layout.num_E());

  const size_t num_outputs = layout.inputs.size();
  Reserve(owner, &d.host_outputs, num_outputs * sizeof(RansacPairOutput), "RANSAC host outputs");
  Reserve(owner, &d.host_masks, layout.mask_bytes(), "RANSAC host masks");
  const RansacPairOutput* outputs = d.host_outputs.host<RansacPairOutput>();
  const uint8_t* masks = d.host_masks.host<uint8_t>();
  CUDA_CHECK(cudaMemcpyAsync(d.host_outputs.host<RansacPairOutput>(), d.outputs.as<RansacPairOutput>(),
                             num_outputs * sizeof(RansacPairOutput), cudaMemcpyDeviceToHost, d.stream));
  CUDA_CHECK(cudaMemcpyAsync(d.host_masks.host<uint8_t>(), d.masks.as<uint8_t>(), layout.mask_bytes(),
                             cudaMemcpyDeviceToHost, d.stream));
  CUDA_CHECK(cudaEventRecord(d.stop, d.stream));
  // Pinned copies are asynchronous: the host works while the kernels run.
  if (while_running) while_running();
  CUDA_CHECK(cudaStreamSynchronize(d.stream));
  float gpu_ms = 0;
  CUDA_CHECK(cudaEventElapsedTime(&gpu_ms, d.start, d.stop));

  UnpackEstimates(layout, pairs, outputs, masks, F, H, E);
  AddBatchStats(layout, outputs, &d.stats);
  d.stats.seconds_gpu += gpu_ms / 1000.0;
  d.stats.seconds_total += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

namespace {

class GpuBatchVerifier : public BatchVerifier {
 public:
  GpuBatchVerifier(const TwoViewGeometryOptions& options, const GpuVerifierConfig& config)
      : options_(options),
        num_threads_(config.num_threads),
        gpu_index_(config.gpu_index),
        max_calls_(std::min(std::max(config.verifications_in_flight, 1), kMaxGpuVerificationsInFlight)),
        resources_(config.resources ? config.resources : std::make_shared<GpuResources>(config.gpu_index, 0)) {
    // The first estimator now, so that an unusable device fails here.
    estimators_.push_back(std::make_unique<GpuTwoViewRansac>(options, gpu_index_, resources_));
    free_.push_back(estimators_.back().get());
  }

  std::string Name() const override { return "gpu"; }

  int MaxConcurrentCalls() const override { return max_calls_; }

  // Two chunks that wait together share one call: each call lasts as long as
  // its slowest pair, so two chunks pay one such tail instead of two. Four
  // lose again, because the writer then waits for a call twice as long and
  // matching stalls behind the held queue room (300 x 8,192 street on an
  // H200: 1 -> 42.1k, 2 -> 47.5k, 4 -> 38.5k pairs/s, identical geometries;
  // docs/gpu_verification.md).
  size_t ChunksPerCall() const override { return 2; }

  std::string StatsSummary() const override {
    const GpuRansacStats st = SummedStats();
    if (st.pairs == 0 && chunks_on_cpu_.load() == 0) return {};
    auto per_pair = [](long long value, size_t pairs) { return pairs ? static_cast<double>(value) / pairs : 0.0; };
    char line[512];
    std::snprintf(line, sizeof(line),
                  "GPU verification: %zu pairs (%zu with E), device busy %.3f s of %.3f s (summed over up to %d "
                  "chunks at once, E blocks of %d threads); trials per pair F %.0f, "
                  "H %.0f, E %.0f; stopped early (chance, or unable to change the decision) F %lld, "
                  "H %lld, E %lld",
                  st.pairs, st.pairs_E, st.seconds_gpu, st.seconds_total, max_calls_,
                  kEssentialLargeBlockThreads, per_pair(st.trials_F, st.pairs),
                  per_pair(st.trials_H, st.pairs), per_pair(st.trials_E, st.pairs_E), st.early_exits_F,
                  st.early_exits_H, st.early_exits_E);
    std::string summary = line;
    const size_t on_cpu = chunks_on_cpu_.load();
    if (on_cpu > 0) {
      summary += "; CPU fallback: " + std::to_string(on_cpu) +
                 " verification calls found no room in GPU memory and were verified on the CPU";
    }
    return summary;
  }

  size_t CallsWithoutDeviceMemory() const override { return chunks_on_cpu_.load(); }

  std::vector<TwoViewGeometry> Verify(const std::vector<VerificationPair>& pairs) override {
    const size_t n = pairs.size();
    std::vector<TwoViewGeometry> geometries(n);
    std::vector<TwoViewPoints> points(n);
    std::vector<EssentialPoints> essential_points(n);
    std::vector<char> estimated(n, 0), calibrated(n, 0);
    ParallelFor(n, num_threads_, [&](size_t k) {
      const VerificationPair& pair = pairs[k];
      if (TooFewMatchesForTwoView(pair.matches->size(), options_)) return;
      points[k] = PrepareTwoViewPoints(*pair.points1, *pair.points2, *pair.matches);
      estimated[k] = 1;
      calibrated[k] = TwoViewIsCalibrated(*pair.camera1, *pair.camera2);
      if (calibrated[k]) {
        essential_points[k] = PrepareEssentialPoints(*pair.camera1, *pair.camera2, points[k].pixels, options_);
      }
    });
    std::vector<size_t> batch;
    std::vector<const TwoViewPoints*> batch_points;
    std::vector<const EssentialPoints*> batch_essential;
    std::vector<uint64_t> batch_seeds;
    for (size_t k = 0; k < n; ++k) {
      if (!estimated[k]) continue;
      batch.push_back(k);
      batch_points.push_back(&points[k]);
      batch_seeds.push_back(pairs[k].random_seed);
      batch_essential.push_back(calibrated[k] ? &essential_points[k] : nullptr);
    }
    std::vector<TwoViewModelEstimate> F, H, E_batch, E(n);
    try {
      EstimatorLease ransac(this);
      ransac->Estimate(batch_points, batch_seeds, batch_essential, &F, &H, &E_batch);
    } catch (const DeviceMemoryError&) {
      // No room on the device for this call's buffers: the CPU verifies it,
      // as the matchers go on on the CPU.
      ++chunks_on_cpu_;
      return CpuVerifier()->Verify(pairs);
    }
    for (size_t i = 0; i < batch.size(); ++i) E[batch[i]] = std::move(E_batch[i]);
    ParallelFor(batch.size(), num_threads_, [&](size_t i) {
      const size_t k = batch[i];
      geometries[k] = DecideTwoViewGeometry(*pairs[k].camera1, *pairs[k].camera2, points[k].pixels,
                                            *pairs[k].matches, calibrated[k] != 0, F[i], H[i], E[k],
                                            PairOptions(pairs[k]));
    });
    for (size_t k = 0; k < n; ++k) {
      if (!estimated[k]) geometries[k].config = kDegenerate;
    }
    return geometries;
  }

 private:
  TwoViewGeometryOptions PairOptions(const VerificationPair& pair) const {
    TwoViewGeometryOptions options = options_;
    options.random_seed = pair.random_seed;
    return options;
  }

  // One estimator (streams and buffers) per Verify call in flight, made on
  // first need and handed back when the call returns.
  class EstimatorLease {
   public:
    explicit EstimatorLease(GpuBatchVerifier* owner) : owner_(owner) {
      std::unique_lock<std::mutex> lock(owner_->mutex_);
      if (owner_->free_.empty()) {
        owner_->estimators_.push_back(
            std::make_unique<GpuTwoViewRansac>(owner_->options_, owner_->gpu_index_, owner_->resources_));
        owner_->free_.push_back(owner_->estimators_.back().get());
      }
      estimator_ = owner_->free_.back();
      owner_->free_.pop_back();
    }
    ~EstimatorLease() {
      std::lock_guard<std::mutex> lock(owner_->mutex_);
      owner_->free_.push_back(estimator_);
    }
    EstimatorLease(const EstimatorLease&) = delete;
    EstimatorLease& operator=(const EstimatorLease&) = delete;
    GpuTwoViewRansac* operator->() const { return estimator_; }

   private:
    GpuBatchVerifier* owner_;
    GpuTwoViewRansac* estimator_ = nullptr;
  };

  GpuRansacStats SummedStats() const {
    std::lock_guard<std::mutex> lock(mutex_);
    GpuRansacStats sum;
    for (const auto& estimator : estimators_) {
      const GpuRansacStats& st = estimator->stats();
      sum.pairs += st.pairs;
      sum.points += st.points;
      sum.seconds_total += st.seconds_total;
      sum.seconds_gpu += st.seconds_gpu;
      sum.trials_F += st.trials_F;
      sum.trials_H += st.trials_H;
      sum.local_refits_F += st.local_refits_F;
      sum.local_refits_H += st.local_refits_H;
      sum.pairs_E += st.pairs_E;
      sum.trials_E += st.trials_E;
      sum.local_refits_E += st.local_refits_E;
      sum.early_exits_F += st.early_exits_F;
      sum.early_exits_H += st.early_exits_H;
      sum.early_exits_E += st.early_exits_E;
    }
    return sum;
  }

  BatchVerifier* CpuVerifier() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!cpu_verifier_) cpu_verifier_ = CreateCpuBatchVerifier(options_, num_threads_);
    return cpu_verifier_.get();
  }

  TwoViewGeometryOptions options_;
  int num_threads_;
  int gpu_index_;
  int max_calls_;
  std::shared_ptr<GpuResources> resources_;  // outlives the estimators
  std::atomic<size_t> chunks_on_cpu_{0};
  std::unique_ptr<BatchVerifier> cpu_verifier_;  // made on the first fallback
  mutable std::mutex mutex_;
  std::vector<std::unique_ptr<GpuTwoViewRansac>> estimators_;
  std::vector<GpuTwoViewRansac*> free_;
};

}  // namespace

std::unique_ptr<BatchVerifier> CreateGpuBatchVerifier(const TwoViewGeometryOptions& options,
                                                      const GpuVerifierConfig& config) {
  return std::make_unique<GpuBatchVerifier>(options, config);
}

std::unique_ptr<BatchVerifier> CreateGpuBatchVerifier(const TwoViewGeometryOptions& options, int gpu_index,
                                                      int num_threads) {
  GpuVerifierConfig config;
  config.gpu_index = gpu_index;
  config.num_threads = num_threads;
  return CreateGpuBatchVerifier(options, config);
}

}  // namespace cuda
}  // namespace cashash
