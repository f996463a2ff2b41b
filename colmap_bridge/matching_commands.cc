#include "colmap_bridge/matching_commands.h"

#include <atomic>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <unordered_set>

#include "cashash/feature_matcher.h"
#include "cashash/matching_pipeline.h"
#include "cashash/pair_generation.h"
#include "cashash/pair_id.h"
#include "colmap_bridge/command_options.h"
#include "colmap_bridge/database.h"
#include "colmap_bridge/database_pipeline_io.h"
#include "colmap_bridge/pair_list.h"
#ifdef CASHASH_WITH_CUDA
#include "cashash_cuda/gpu_feature_matcher.h"
#endif

namespace cashash {
namespace colmap {
namespace {

std::atomic<bool> g_stop_requested{false};

// First Ctrl-C: finish and commit the chunks in flight, then stop. A second
// one ends the process at once (the database stays valid: every chunk is one
// transaction).
extern "C" void HandleInterrupt(int) {
  if (g_stop_requested.exchange(true)) {
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
  }
}

void PrintHeading(const std::string& title) {
  std::cout << "\n" << std::string(78, '=') << "\n" << title << "\n" << std::string(78, '=') << "\n" << std::endl;
}

std::string FormatDuration(double seconds) {
  const long s = static_cast<long>(seconds + 0.5);
  std::ostringstream out;
  out << s / 3600 << ":" << std::setw(2) << std::setfill('0') << (s / 60) % 60 << ":" << std::setw(2)
      << std::setfill('0') << s % 60;
  return out.str();
}

// The hashing mean comes from at most this many images spread evenly over
// the database, so that a huge database is not read twice for it.
constexpr size_t kMaxImagesForMean = 100;

MeanDescriptor ComputeDatabaseMean(DatabaseFeatureSource& source, const std::vector<image_t>& image_ids) {
  std::vector<FeatureDescriptors> sample;
  const size_t n = image_ids.size();
  const size_t count = std::min(n, kMaxImagesForMean);
  for (size_t k = 0; k < count; ++k) {
    sample.push_back(source.database().ReadDescriptors(image_ids[k * n / count]));
  }
  std::vector<const FeatureDescriptors*> pointers;
  for (const FeatureDescriptors& d : sample) pointers.push_back(&d);
  return ComputeMeanDescriptor(pointers);
}

#ifdef CASHASH_WITH_CUDA
int FirstGpuIndex(const std::string& gpu_index) {
  const std::string first = gpu_index.substr(0, gpu_index.find(','));
  try {
    return std::max(0, std::stoi(first));
  } catch (const std::exception&) {
    throw std::runtime_error("--FeatureMatching.gpu_index: expected an integer or a comma-separated list, got '" +
                             gpu_index + "'");
  }
}
#endif

std::unique_ptr<FeatureMatcher> CreateMatcher(const MatcherCommandOptions& options, const MeanDescriptor& mean) {
  if (options.use_gpu) {
#ifdef CASHASH_WITH_CUDA
    const int gpu_index = FirstGpuIndex(options.gpu_index);
    std::string reason;
    if (cuda::CudaDeviceUsable(gpu_index, &reason)) {
      return cuda::CreateGpuFeatureMatcher(options.sift, options.cashash, mean, gpu_index);
    }
    std::cerr << "WARNING: no usable CUDA device (" << reason << "); matching on the CPU" << std::endl;
#else
    std::cerr << "WARNING: cashash was built without CUDA; matching on the CPU" << std::endl;
#endif
  }
  return CreateCpuFeatureMatcher(options.sift, options.cashash, mean);
}

void WarnAboutSmallImages(DatabaseFeatureSource& source, const std::vector<image_t>& image_ids) {
  for (image_t image_id : image_ids) {
    const size_t rows = source.database().NumDescriptors(image_id);
    if (rows < 2) {
      std::cerr << "WARNING: image " << image_id << " (" << source.image(image_id).name << ") has " << rows
                << " feature" << (rows == 1 ? "" : "s") << "; its pairs get empty matches" << std::endl;
    }
  }
}

// Runs the pipeline over `chunks` of pairs and prints COLMAP-style progress
// and a closing summary.
int MatchChunks(const MatcherCommandOptions& options, DatabaseFeatureSource& source,
                const std::vector<image_t>& image_ids, std::vector<PairChunk> chunks, size_t num_pairs_requested) {
  if (!options.overwrite) {
    const std::unordered_set<pair_t> done = source.database().ReadCompletedPairIds();
    if (!done.empty()) {
      chunks = RemovePairs(std::move(chunks), [&](const ImagePair& pair) {
        return done.count(ImagePairToPairId(pair.first, pair.second)) > 0;
      });
    }
  }
  size_t num_pairs = 0;
  for (const PairChunk& chunk : chunks) num_pairs += chunk.pairs.size();
  const size_t num_skipped = num_pairs_requested - num_pairs;
  if (num_skipped > 0) {
    std::cout << "Skipping " << num_skipped << " of " << num_pairs_requested
              << " pairs already in the database (use --overwrite 1 to match them again)" << std::endl;
  }
  if (num_pairs == 0) {
    std::cout << "Nothing to match." << std::endl;
    return EXIT_SUCCESS;
  }
  WarnAboutSmallImages(source, image_ids);

  const MeanDescriptor mean = ComputeDatabaseMean(source, image_ids);
  std::unique_ptr<FeatureMatcher> matcher = CreateMatcher(options, mean);
  DatabaseResultSink sink(options.database_path, !options.skip_geometric_verification);

  PipelineOptions pipeline_options;
  pipeline_options.num_threads = options.sift.num_threads;
  pipeline_options.skip_geometric_verification = options.skip_geometric_verification;
  pipeline_options.two_view = options.two_view;
  MatchingPipeline pipeline(pipeline_options, &source, matcher.get(), &sink);
  pipeline.SetProgressCallback([](const PipelineProgress& p) {
    const double rate = p.elapsed_seconds > 0 ? p.pairs_done / p.elapsed_seconds : 0.0;
    const double eta = rate > 0 ? (p.pairs_total - p.pairs_done) / rate : 0.0;
    std::cout << "Matching block [" << p.chunk->block_i + 1 << "/" << p.chunk->num_blocks << ", "
              << p.chunk->block_j + 1 << "/" << p.chunk->num_blocks << "] in " << std::fixed << std::setprecision(3)
              << p.chunk_seconds << "s  (" << p.pairs_done << "/" << p.pairs_total << " pairs, "
              << std::setprecision(1) << 100.0 * p.pairs_done / p.pairs_total << "%, " << rate << " pairs/s, ETA "
              << FormatDuration(eta) << ")" << std::endl;
  });
  g_stop_requested = false;
  std::signal(SIGINT, HandleInterrupt);
  pipeline.SetStopFlag(&g_stop_requested);
  std::cout << "Matcher: " << matcher->Name() << std::endl;

  const PipelineStats stats = pipeline.Run(chunks);
  std::signal(SIGINT, SIG_DFL);

  std::cout << std::fixed << std::setprecision(3);
  std::cout << "Elapsed time: " << stats.seconds_total / 60.0 << " [minutes]" << std::endl;
  std::cout << "Summary: " << stats.pairs_done << " pairs in " << stats.seconds_total << " s ("
            << std::setprecision(1) << (stats.seconds_total > 0 ? stats.pairs_done / stats.seconds_total : 0.0)
            << " pairs/s) with " << matcher->Name() << "; " << stats.raw_matches << " raw matches, "
            << stats.verified_pairs << " verified pairs, " << stats.inlier_matches << " inlier matches"
            << std::endl;
  std::cout << std::setprecision(3) << "Time: loading " << stats.seconds_loading << " s, matching "
            << stats.seconds_matching << " s, verification " << stats.seconds_verification << " s, writing "
            << stats.seconds_writing << " s" << std::endl;
  if (stats.stopped) {
    std::cout << "Stopped after " << stats.pairs_done << " of " << stats.pairs_total
              << " pairs; every finished block is committed, run again to resume." << std::endl;
    return 130;
  }
  return EXIT_SUCCESS;
}

std::vector<image_t> ImageIds(const DatabaseFeatureSource& source) {
  std::vector<image_t> ids;
  for (const Image& image : source.images()) ids.push_back(image.image_id);
  return ids;
}

// Parses and checks options; returns -1 when the command should go on.
int PrepareOptions(const std::string& command, int argc, const char* const* argv, MatcherCommandOptions* options) {
  switch (ParseMatcherCommandOptions(command, argc, argv, options)) {
    case ParseOutcome::kHelpShown:
      return EXIT_SUCCESS;
    case ParseOutcome::kError:
      return EXIT_FAILURE;
    case ParseOutcome::kRun:
      break;
  }
  const std::string problem = CheckMatcherCommandOptions(*options);
  if (!problem.empty()) {
    std::cerr << "ERROR: " << problem << std::endl;
    return EXIT_FAILURE;
  }
  return -1;
}

template <typename Body>
int RunGuarded(Body body) {
  try {
    return body();
  } catch (const std::exception& e) {
    std::cerr << "ERROR: " << e.what() << std::endl;
    return EXIT_FAILURE;
  }
}

}  // namespace

int RunExhaustiveMatcher(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("exhaustive_matcher", argc, argv, &options);
  if (early >= 0) return early;
  return RunGuarded([&]() {
    DatabaseFeatureSource source(options.database_path);
    PrintHeading("Exhaustive feature matching");
    const std::vector<image_t> image_ids = ImageIds(source);
    if (image_ids.size() < 2) {
      std::cerr << "WARNING: table images of " << options.database_path << " holds " << image_ids.size()
                << " image" << (image_ids.size() == 1 ? "" : "s") << "; nothing to match" << std::endl;
      return EXIT_SUCCESS;
    }
    std::vector<PairChunk> chunks = ExhaustivePairChunks(image_ids, options.block_size);
    const size_t n = image_ids.size();
    return MatchChunks(options, source, image_ids, std::move(chunks), n * (n - 1) / 2);
  });
}

int RunMatchesImporter(int argc, const char* const* argv) {
  MatcherCommandOptions options;
  const int early = PrepareOptions("matches_importer", argc, argv, &options);
  if (early >= 0) return early;
  if (options.match_type != "pairs") {
    std::cerr << "ERROR: --match_type '" << options.match_type
              << "' is not supported; cashash matches and verifies 'pairs' lists" << std::endl;
    return EXIT_FAILURE;
  }
  if (options.match_list_path.empty()) {
    std::cerr << "ERROR: --match_list_path is required" << std::endl;
    return EXIT_FAILURE;
  }
  return RunGuarded([&]() {
    DatabaseFeatureSource source(options.database_path);
    PrintHeading("Custom feature matching");
    std::unordered_map<std::string, image_t> ids_by_name;
    for (const Image& image : source.images()) ids_by_name.emplace(image.name, image.image_id);
    std::ifstream file(options.match_list_path);
    if (!file) throw std::runtime_error("cannot open --match_list_path " + options.match_list_path);
    const std::vector<ImagePair> pairs = ParsePairList(file, options.match_list_path, ids_by_name);
    std::vector<image_t> image_ids;
    for (const ImagePair& pair : pairs) {
      image_ids.push_back(pair.first);
      image_ids.push_back(pair.second);
    }
    std::sort(image_ids.begin(), image_ids.end());
    image_ids.erase(std::unique(image_ids.begin(), image_ids.end()), image_ids.end());
    const size_t block = static_cast<size_t>(options.block_size);
    std::vector<PairChunk> chunks = ListPairChunks(pairs, block * block, 2 * block);
    return MatchChunks(options, source, image_ids, std::move(chunks), pairs.size());
  });
}

}  // namespace colmap
}  // namespace cashash
