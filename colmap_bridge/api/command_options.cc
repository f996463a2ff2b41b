#include "colmap_bridge/api/command_options.h"

#include <algorithm>
#include <iostream>
#include <sstream>

#include <boost/program_options.hpp>

#include "cashash/matching/table_shape.h"
#include "cashash/pipeline/schedule_sizing.h"
#include "colmap_bridge/api/run_resolution.h"
#include "colmap_bridge/database.h"

namespace po = boost::program_options;

namespace cashash {
namespace colmap {
namespace {

template <typename T>
std::string DefaultText(const T& value) {
  std::ostringstream out;
  out << std::boolalpha << value;
  return out.str();
}

// Binds one variable to several option names (COLMAP 3.8 and 4.x spell the
// same setting differently). No boost default is registered: a default would
// be "given" under every name and could override the name the user typed.
class OptionTable {
 public:
  explicit OptionTable(po::options_description* description) : description_(description) {}

  template <typename T>
  void Add(const std::vector<std::string>& names, T* value, const std::string& help) {
    Add(names, value, help, DefaultText(*value));
  }

  // With the default shown as `shown` (a value chosen for the run shows
  // what it is where nothing decides otherwise).
  template <typename T>
  void Add(const std::vector<std::string>& names, T* value, const std::string& help, const std::string& shown) {
    const std::string text = help + " (=" + shown + ")";
    for (size_t i = 0; i < names.size(); ++i) {
      const std::string alias_note = i == 0 ? "" : " [alias of --" + names[0] + "]";
      description_->add_options()(names[i].c_str(), po::value<T>(value), (text + alias_note).c_str());
    }
  }

 private:
  po::options_description* description_;
};

// retrieval_matcher / vocab_tree_matcher: COLMAP's VocabTreeMatching.*
// names where they mean the same, Retrieval.* for the hash-code words.
void AddRetrievalOptions(OptionTable* table, MatcherCommandOptions* o) {
  RetrievalOptions& r = o->retrieval;
  table->Add({"VocabTreeMatching.num_images"}, &r.num_images, "Each image is matched with this many most similar images");
  table->Add({"VocabTreeMatching.num_nearest_neighbors"}, &r.num_nearest_neighbors,
             "Visual words a query feature looks up per table: its own cell and the nearest ones across its least "
             "certain hash bits");
  table->Add({"VocabTreeMatching.max_num_features"}, &r.max_num_features,
             "Features indexed per image, largest scales first (-1: all)");
  table->Add({"VocabTreeMatching.num_checks"}, &o->vocab_tree_num_checks,
             "COLMAP's tree search depth: accepted, not used (no tree is searched)");
  table->Add({"VocabTreeMatching.vocab_tree_path"}, &o->vocab_tree_path,
             "COLMAP's vocabulary tree: accepted, not used (the words come from the hash codes; a warning says so)");
  table->Add({"Retrieval.num_tables"}, &r.num_tables, "Hash tables, each giving every feature one visual word");
  table->Add({"Retrieval.bits_per_word"}, &r.bits_per_word,
             "Bits of a visual word; 0 = log2(median features per image) + 10, in [8, 24]");
  table->Add({"Retrieval.max_word_image_fraction"}, &r.max_word_image_fraction,
             "Words held by more than this share of the images are stop words, left out");
  table->Add({"TransitiveMatching.num_iterations", "transitive"}, &o->transitive_rounds,
             "After the retrieved pairs: rounds of matching the pairs the verified graph implies (i-j, j-k "
             "verified: i-k), as COLMAP's transitive_matcher; 0 = none");
}

// COLMAP's SequentialMatching.* options, with its names and defaults.
void AddSequentialMatchingOptions(OptionTable* table, SequentialPairingOptions* o) {
  table->Add({"SequentialMatching.overlap"}, &o->overlap, "Images after each image (in name order) it is matched with");
  table->Add({"SequentialMatching.quadratic_overlap"}, &o->quadratic_overlap,
             "Match the images 1, 2, 4, ..., 2^(overlap-1) places on instead of the next overlap images");
  table->Add({"SequentialMatching.expand_rig_images"}, &o->expand_rig_images,
             "Match the images of a rig frame with each other and with the neighbouring frames' images (databases "
             "with rigs and frames)");
  table->Add({"SequentialMatching.loop_detection"}, &o->loop_detection,
             "Also match every loop_detection_period-th image with the images most like it (image retrieval from "
             "the cascade's codes; no vocabulary tree)");
  table->Add({"SequentialMatching.loop_detection_period"}, &o->loop_detection_period,
             "Every how many images (in name order) a loop query is made");
  table->Add({"SequentialMatching.loop_detection_num_images"}, &o->loop_detection_num_images,
             "Images retrieved per loop query");
  table->Add({"SequentialMatching.loop_detection_min_index_distance"}, &o->loop_detection_min_index_distance,
             "Retrieved images fewer than this many places from the query are no loop pairs (0: no limit)");
  const std::string ignored = " (COLMAP's vocabulary tree; accepted and not used)";
  table->Add({"SequentialMatching.loop_detection_num_nearest_neighbors"}, &o->loop_detection_num_nearest_neighbors,
             "Visual words a query feature looks up per hash table (at most " +
                 std::to_string(RetrievalOptions::kMaxNearestNeighbors) + " are used)");
  table->Add({"SequentialMatching.loop_detection_num_checks"}, &o->loop_detection_num_checks,
             "Nearest-neighbour checks of the tree search" + ignored);
  table->Add({"SequentialMatching.loop_detection_num_images_after_verification"},
             &o->loop_detection_num_images_after_verification, "Images kept after spatial verification" + ignored);
  table->Add({"SequentialMatching.loop_detection_max_num_features"}, &o->loop_detection_max_num_features,
             "Features indexed per image, largest scales first (-1: all)");
  table->Add({"SequentialMatching.vocab_tree_path"}, &o->vocab_tree_path, "Vocabulary tree file" + ignored);
  table->Add({"SequentialMatching.num_threads"}, &o->num_threads, "Threads of the loop retrieval (reading, hashing, indexing, querying), -1 for all cores");
}

// COLMAP's SpatialMatching.* options, with its names and defaults.
void AddSpatialMatchingOptions(OptionTable* table, SpatialPairingOptions* o) {
  table->Add({"SpatialMatching.ignore_z"}, &o->ignore_z, "Compare positions without their height");
  table->Add({"SpatialMatching.max_num_neighbors"}, &o->max_num_neighbors, "Most neighbours matched per image");
  table->Add({"SpatialMatching.min_num_neighbors"}, &o->min_num_neighbors,
             "Fewest neighbours matched per image, beyond max_distance if need be");
  table->Add({"SpatialMatching.max_distance"}, &o->max_distance,
             "Largest distance to a neighbour (metres for GPS priors, else the priors' unit)");
  table->Add({"SpatialMatching.is_gps"}, &o->is_gps,
             "COLMAP 3.8 databases: read the prior_tx, prior_ty, prior_tz columns of table images as latitude, "
             "longitude, altitude (0: as Cartesian); pose_priors name their own coordinate system");
  table->Add({"SpatialMatching.num_threads"}, &o->num_threads, "Threads of the neighbour search, -1 for all cores");
}

// The run as a whole: seed, resume, how rows are written.
void AddRunOptions(OptionTable* table, MatcherCommandOptions* o) {
  table->Add({"random_seed"}, &o->random_seed, "Seed of the hash projections and of RANSAC");
  table->Add({"overwrite"}, &o->overwrite, "Re-match pairs that already have results (default: resume, skipping them)");
  table->Add({"write_empty_pairs"}, &o->write_empty_pairs,
             "Write matches and two_view_geometries rows for pairs without a match, as COLMAP does (0: record "
             "them in table cashash_empty_pairs only, so that a rerun skips them)");
  table->Add({"database_commit_seconds"}, &o->database_commit_seconds,
             "Seconds a write transaction takes chunks before it commits, or until they hold 16 MiB of matches (0: "
             "one transaction per chunk); a kill loses the chunks not yet committed, which a rerun matches again");
  table->Add({"database_synchronous"}, &o->database_synchronous,
             "SQLite's synchronous setting for writing: FULL (safe), NORMAL (a power loss or OS crash may undo "
             "the last commits; the file stays valid) or OFF (a power loss or OS crash may damage the database; "
             "COLMAP's own setting)");
}

// COLMAP's FeatureMatching.* and SiftMatching.* options.
void AddFeatureMatchingOptions(OptionTable* table, MatcherCommandOptions* o) {
  table->Add({"FeatureMatching.num_threads", "SiftMatching.num_threads"}, &o->sift.num_threads,
             "CPU threads, -1 for all cores");
  table->Add({"FeatureMatching.use_gpu", "SiftMatching.use_gpu"}, &o->use_gpu,
             "Match on the GPU (falls back to the CPU with a warning where there is none)");
  table->Add({"FeatureMatching.gpu_index", "SiftMatching.gpu_index"}, &o->gpu_index,
             "CUDA device index, -1 for the first device; a list (0,1) matches on several devices, each block pair split among them");
  table->Add({"FeatureMatching.max_num_matches", "SiftMatching.max_num_matches"}, &o->sift.max_num_matches,
             "Features per image considered (first rows)");
  table->Add({"FeatureMatching.guided_matching", "SiftMatching.guided_matching"}, &o->guided_matching,
             "COLMAP's guided matching (not supported)");
  table->Add({"FeatureMatching.skip_geometric_verification"}, &o->skip_geometric_verification,
             "Write raw matches only, no two_view_geometries");
  table->Add({"SiftMatching.max_ratio"}, &o->sift.max_ratio, "Lowe's ratio test on descriptor angles");
  table->Add({"SiftMatching.max_distance"}, &o->sift.max_distance, "Largest descriptor angle (radians) accepted");
  table->Add({"SiftMatching.cross_check"}, &o->sift.cross_check, "Keep mutual best matches only");
}

// COLMAP's TwoViewGeometry.* options and the verification's own.
void AddTwoViewGeometryOptions(OptionTable* table, MatcherCommandOptions* o) {
  table->Add({"TwoViewGeometry.min_num_inliers", "SiftMatching.min_num_inliers"}, &o->two_view.min_num_inliers,
             "Fewest inliers of a verified pair");
  table->Add({"TwoViewGeometry.max_error", "SiftMatching.max_error"}, &o->two_view.max_error,
             "RANSAC threshold in pixels");
  table->Add({"TwoViewGeometry.confidence", "SiftMatching.confidence"}, &o->two_view.confidence,
             "RANSAC confidence");
  table->Add({"TwoViewGeometry.min_num_trials"}, &o->two_view.min_num_trials, "RANSAC minimum trials");
  table->Add({"TwoViewGeometry.max_num_trials", "SiftMatching.max_num_trials"}, &o->two_view.max_num_trials,
             "RANSAC maximum trials");
  table->Add({"TwoViewGeometry.min_inlier_ratio", "SiftMatching.min_inlier_ratio"}, &o->two_view.min_inlier_ratio,
             "RANSAC minimum inlier ratio");
  table->Add({"TwoViewGeometry.min_E_F_inlier_ratio"}, &o->two_view.min_E_F_inlier_ratio,
             "E inliers / F inliers above which a calibrated pair keeps E");
  table->Add({"TwoViewGeometry.max_H_inlier_ratio"}, &o->two_view.max_H_inlier_ratio,
             "H inliers / F inliers above which a pair is planar or panoramic");
  table->Add({"TwoViewGeometry.watermark_min_inlier_ratio"}, &o->two_view.watermark_min_inlier_ratio,
             "Share of border inliers explained by a translation that marks a watermark");
  table->Add({"TwoViewGeometry.watermark_border_size"}, &o->two_view.watermark_border_size,
             "Border band for the watermark test, relative to the image diagonal");
  table->Add({"TwoViewGeometry.detect_watermark"}, &o->two_view.detect_watermark, "Run the watermark test");
  table->Add({"TwoViewGeometry.early_exit"}, &o->two_view.early_exit,
             "Stop RANSAC early on pairs whose matches look like chance, and H and E once they cannot change the "
             "decision (0 = COLMAP's full trial budget)");
  table->Add({"TwoViewGeometry.early_exit_max_risk"}, &o->two_view.early_exit_max_risk,
             "Largest chance, under the fitted chance model, that the full budget would have verified a stopped pair");
  table->Add({"TwoViewGeometry.sprt"}, &o->two_view.sprt,
             "Reject wrong RANSAC hypotheses by a sequential test before scoring them over all matches "
             "(0 = score every hypothesis as COLMAP does)");
  table->Add({"TwoViewGeometry.sprt_max_risk"}, &o->two_view.sprt_max_risk,
             "Largest chance that the sequential test rejects a model which would have beaten the best so far");
}

// Block size and the memory caps the schedule is sized from; the trace.
void AddScheduleOptions(OptionTable* table, MatcherCommandOptions* o) {
  table->Add({"ExhaustiveMatching.block_size"}, &o->block_size,
             "Images per block (default: from the memory caps, at most 50)", std::to_string(kDefaultBlockSize));
  table->Add({"max_host_memory"}, &o->max_host_memory,
             "Host memory for features, e.g. 16G or 4096 (MiB); default half the physical memory");
  table->Add({"max_gpu_memory"}, &o->max_gpu_memory,
             "GPU memory for matching, e.g. 8G or 4096 (MiB); default the device's free memory");
  table->Add({"pipeline_trace_path"}, &o->pipeline_trace_path,
             "Write each chunk's stage intervals to this CSV file (scripts/bench/pipeline_trace_summary.py reads "
             "it); under MPI each rank writes PATH.rankN");
}

// CasHash.*: the matcher and its tables. The matcher is read as text into
// `matcher_name`, converted once the command line is parsed.
void AddCasHashOptions(OptionTable* table, MatcherCommandOptions* o, std::string* matcher_name) {
  table->Add({"CasHash.matcher"}, matcher_name,
             "auto (chosen from the data: on the GPU the cascade with the exact rematch, on the CPU the cascade "
             "with the rematch of the pairs near the verification threshold) | cascade | bruteforce (exact reference)");
  table->Add({"CasHash.num_tables"}, &o->cashash.num_tables,
             "First-level hash tables; 0 = chosen with the bits from the features per image: while the exact "
             "rematch decides 8 x 8 below 8192, 3 x 9 from there, 3 x 10 from 16384; where the cascade's matches "
             "are kept 8 x 7 below 16384, 8 x 8 from there");
  table->Add({"CasHash.bits_per_table"}, &o->cashash.bits_per_table,
             "Bits per first-level table; 0 = chosen from the features per image (see CasHash.num_tables)");
  table->Add({"CasHash.tau"}, &o->cashash.tau,
             "Largest 128-bit remap Hamming distance ranked; 0 = chosen: " + std::to_string(kCascadeTauForScreening) +
                 " while the exact rematch decides the pairs that may verify, " +
                 std::to_string(kCascadeTauForPrecision) +
                 " where the cascade's own matches are kept (no rematch, guided matching)");
  table->Add({"CasHash.top_k"}, &o->cashash.top_k, "Candidates per query whose exact distance is computed");
  table->Add({"CasHash.exact_rematch_min_matches"}, &o->cashash.exact_rematch_min_matches,
             "Pairs with at least this many cascade matches are matched again exactly (0 = keep the cascade's); "
             "not given: " + std::to_string(kDefaultRematchMinMatches) + ", or " +
                 std::to_string(kBucketScreeningRematchMinMatches) +
                 " with the 3 screening tables chosen from 8192 features per image",
              std::to_string(kDefaultRematchMinMatches));
  table->Add({"CasHash.exact_rematch_max_matches"}, &o->cashash.exact_rematch_max_matches,
             "When > 0, only pairs with fewer cascade matches than this are matched again exactly; 0 = no upper "
             "bound (CasHash.matcher auto on the CPU: 12 to 63 unless either rematch option is given)");
}

// GuidedMatching.*: Ga-CasHash.
void AddGuidedMatchingOptions(OptionTable* table, GuidedMatchingOptions* o) {
  table->Add({"GuidedMatching.enabled"}, &o->enabled,
             "Ga-CasHash: match the top-scale features first, then exactly only the pairs that show overlap (within "
             "the epipolar bands where F explains them)");
  table->Add({"GuidedMatching.top_scale_fraction"}, &o->top_scale_fraction,
             "Share of each image's features (largest scales) matched in stage 1");
  table->Add({"GuidedMatching.min_num_matches"}, &o->min_num_matches,
             "Fewest stage-1 matches for which F is estimated");
  table->Add({"GuidedMatching.min_inlier_ratio"}, &o->min_inlier_ratio,
             "Smallest share of stage-1 matches that are F inliers for a pair to be matched in stage 2");
  table->Add({"GuidedMatching.max_epipolar_distance"}, &o->max_epipolar_distance,
             "Half-width in pixels of the band around the stage-1 epipolar lines that stage-2 matches must lie in "
             "(0: 16 for the filter of exact matches, 4 for the paper's search within the band)");
  table->Add({"GuidedMatching.unguided_fallback"}, &o->unguided_fallback,
             "Match pairs that stage 1 cannot guide but that have at least fallback_min_num_matches stage-1 "
             "matches exactly, without the band (not in the paper)");
  table->Add({"GuidedMatching.fallback_min_num_matches"}, &o->fallback_min_num_matches,
             "Fewest stage-1 matches for which a pair that is not guided is matched without the band");
  table->Add({"GuidedMatching.restrict_search_to_band"}, &o->restrict_search_to_band,
             "The paper's stage 2: search candidates within the band only (accepts matches that are ambiguous in "
             "the whole image); 0 filters exact matches by the band");
}

}  // namespace

// The option table reads as one list in --help order: each Add*Options adds
// its group, all binding into the one options_description parsed below.
ParseOutcome ParseMatcherCommandOptions(const std::string& command, int argc, const char* const* argv,
                                        MatcherCommandOptions* options) {
  po::options_description description("cashash " + command + " options");
  description.add_options()("help,h", "Print this help");
  OptionTable table(&description);
  MatcherCommandOptions& o = *options;
  table.Add({"database_path"}, &o.database_path, "COLMAP database to read features from and write matches to");
  if (command == "matches_importer") {
    table.Add({"match_list_path"}, &o.match_list_path, "Text file with one 'name1 name2' pair per line");
    table.Add({"match_type"}, &o.match_type, "Only 'pairs' is supported: match and verify the listed pairs");
  }
  if (command == "retrieval_matcher" || command == "vocab_tree_matcher") {
    AddRetrievalOptions(&table, &o);
  }
  if (command == "sequential_matcher") AddSequentialMatchingOptions(&table, &o.sequential);
  if (command == "spatial_matcher") AddSpatialMatchingOptions(&table, &o.spatial);
  AddRunOptions(&table, &o);
  AddFeatureMatchingOptions(&table, &o);
  AddTwoViewGeometryOptions(&table, &o);
  AddScheduleOptions(&table, &o);
  std::string matcher_name = MatcherTypeToString(o.cashash.matcher);
  AddCasHashOptions(&table, &o, &matcher_name);
  if (command == "guided_matcher") o.guided.enabled = true;
  AddGuidedMatchingOptions(&table, &o.guided);

  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(description).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    std::cerr << "ERROR: " << e.what() << " (see cashash " << command << " --help)" << std::endl;
    return ParseOutcome::kError;
  }
  if (vm.count("help")) {
    std::cout << description << std::endl;
    return ParseOutcome::kHelpShown;
  }
  if (!MatcherTypeFromString(matcher_name, &o.cashash.matcher)) {
    std::cerr << "ERROR: --CasHash.matcher must be 'auto', 'cascade' or 'bruteforce', got '" << matcher_name << "'"
              << std::endl;
    return ParseOutcome::kError;
  }
  o.cashash.random_seed = o.random_seed;
  o.two_view.random_seed = o.random_seed;
  return ParseOutcome::kRun;
}

std::string CheckMatcherCommandOptions(const MatcherCommandOptions& o) {
  if (o.database_path.empty()) return "--database_path is required";
  return CheckRunOptions(o);
}

std::string CheckRunOptions(const MatcherCommandOptions& o) {
  // 0: chosen for the run.
  if (o.block_size < 0 || o.block_size == 1) return "--ExhaustiveMatching.block_size must be >= 2";
  for (const auto& [name, text] : {std::make_pair("--max_host_memory", &o.max_host_memory),
                                   std::make_pair("--max_gpu_memory", &o.max_gpu_memory)}) {
    size_t bytes = 0;
    if (!text->empty() && !ParseMemorySize(*text, &bytes)) {
      return std::string(name) + " must be a size such as 16G, 512M or 4096 (MiB), got '" + *text + "'";
    }
  }
  std::vector<int> gpu_indices;
  const std::string gpu_index_problem = ParseGpuIndices(o.gpu_index, &gpu_indices);
  if (!gpu_index_problem.empty()) return gpu_index_problem;
  if (o.guided_matching) return "--FeatureMatching.guided_matching is not supported by cashash";
  if (o.transitive_rounds < 0) {
    return "--TransitiveMatching.num_iterations must be >= 0, got " + std::to_string(o.transitive_rounds);
  }
  {
    const std::string retrieval_problem = o.retrieval.Check();
    if (!retrieval_problem.empty()) return retrieval_problem;
  }
  if (!(o.database_commit_seconds >= 0 && o.database_commit_seconds <= 3600)) {
    return "--database_commit_seconds must be 0 to 3600, got " + std::to_string(o.database_commit_seconds);
  }
  DiskSync sync;
  if (!ParseDiskSync(o.database_synchronous, &sync)) {
    return "--database_synchronous must be FULL, NORMAL or OFF, got '" + o.database_synchronous + "'";
  }
  if (o.gpu_verifications_in_flight < 1 || o.gpu_verifications_in_flight > 8) {
    return "gpu_verifications_in_flight must be 1 to 8, got " + std::to_string(o.gpu_verifications_in_flight);
  }
  std::string message = o.sift.Check();
  if (!message.empty()) return message;
  message = o.sequential.Check();
  if (!message.empty()) return message;
  message = o.spatial.Check();
  if (!message.empty()) return message;
  CasHashOptions cashash = o.cashash;
  if (cashash.exact_rematch_min_matches == kRematchMinMatchesChosen) {
    cashash.exact_rematch_min_matches = kDefaultRematchMinMatches;
  }
  message = cashash.Check();
  if (!message.empty()) return message;
  if (o.guided.enabled) {
    message = o.guided.Check();
    if (!message.empty()) return message;
    // auto resolves to the cascade (MatcherRule).
    if (o.cashash.matcher == MatcherType::kBruteForce) {
      return "--GuidedMatching.enabled needs --CasHash.matcher cascade or auto (the band filter is part of the "
             "cascade)";
    }
  }
  return o.two_view.Check();
}

std::string ParseGpuIndices(const std::string& gpu_index, std::vector<int>* indices) {
  indices->clear();
  size_t at = 0;
  while (at <= gpu_index.size()) {
    const size_t comma = std::min(gpu_index.find(',', at), gpu_index.size());
    const std::string item = gpu_index.substr(at, comma - at);
    size_t used = 0;
    int value = -1;
    try {
      value = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (item.empty() || used != item.size()) {
      indices->clear();
      return "--FeatureMatching.gpu_index: expected an integer or a comma-separated list, got '" +
             gpu_index + "'";
    }
    value = std::max(0, value);
    if (std::find(indices->begin(), indices->end(), value) == indices->end()) indices->push_back(value);
    at = comma + 1;
  }
  return "";
}

}  // namespace colmap
}  // namespace cashash
