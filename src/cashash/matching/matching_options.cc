#include "cashash/matching/matching_options.h"

#include <sstream>

namespace cashash {

std::string SiftMatchingOptions::Check() const {
  std::ostringstream error;
  if (num_threads != -1 && num_threads < 1) {
    error << "SiftMatching.num_threads must be -1 (all cores) or >= 1, got " << num_threads;
  } else if (!(max_ratio > 0.0)) {
    error << "SiftMatching.max_ratio must be > 0, got " << max_ratio;
  } else if (!(max_distance > 0.0)) {
    error << "SiftMatching.max_distance must be > 0, got " << max_distance;
  } else if (max_num_matches < 1) {
    error << "SiftMatching.max_num_matches must be >= 1, got " << max_num_matches;
  }
  return error.str();
}

std::string CasHashOptions::Check() const {
  // Bucket tables hold 2^bits_per_table offsets per table; past 20 bits the
  // tables cost more memory than the features themselves.
  constexpr int kMaxBitsPerTable = 20;
  constexpr int kMaxTables = 64;
  std::ostringstream error;
  // 0 = chosen from the feature counts (table_shape.h).
  if (num_tables < 0 || num_tables > kMaxTables) {
    error << "CasHash.num_tables must be 0 (from the feature counts) or in [1, " << kMaxTables << "], got "
          << num_tables;
  } else if (bits_per_table < 0 || bits_per_table > kMaxBitsPerTable) {
    error << "CasHash.bits_per_table must be 0 (from the feature counts) or in [1, " << kMaxBitsPerTable
          << "], got " << bits_per_table;
  } else if (tau < kTauChosen || tau > kRemapBits) {
    error << "CasHash.tau must be 0 (chosen for the run) or in [1, " << kRemapBits << "], got " << tau;
  } else if (top_k < 1) {
    error << "CasHash.top_k must be >= 1, got " << top_k;
  } else if (exact_rematch_min_matches < kRematchMinMatchesChosen) {
    error << "CasHash.exact_rematch_min_matches must be -1 (chosen for the run) or >= 0 (0 = off), got "
          << exact_rematch_min_matches;
  } else if (exact_rematch_max_matches < 0) {
    error << "CasHash.exact_rematch_max_matches must be >= 0 (0 = no upper bound), got "
          << exact_rematch_max_matches;
  } else if (exact_rematch_max_matches > 0 && exact_rematch_max_matches <= exact_rematch_min_matches) {
    error << "CasHash.exact_rematch_max_matches must be 0 or above CasHash.exact_rematch_min_matches ("
          << exact_rematch_min_matches << "), got " << exact_rematch_max_matches;
  }
  return error.str();
}

std::string CasHashOptions::CheckDecided() const {
  if (matcher == MatcherType::kAuto) {
    return "--CasHash.matcher auto is chosen per run by ResolveRun; name cascade or bruteforce to build a matcher "
           "directly";
  }
  if (tau == kTauChosen) {
    return "--CasHash.tau 0 is chosen per run by ResolveRun; give a value > 0 to build a matcher directly";
  }
  if (exact_rematch_min_matches == kRematchMinMatchesChosen) {
    return "--CasHash.exact_rematch_min_matches -1 is chosen per run by ResolveRun; give 0 (off) or a threshold to "
           "build a matcher directly";
  }
  return "";
}

bool CascadeOnlyScreens(int exact_rematch_min_matches, bool guided, int exact_rematch_max_matches) {
  return exact_rematch_min_matches > 0 && exact_rematch_max_matches == 0 && !guided;
}

int ChooseCascadeTau(int exact_rematch_min_matches, bool guided, int exact_rematch_max_matches) {
  return CascadeOnlyScreens(exact_rematch_min_matches, guided, exact_rematch_max_matches) ? kCascadeTauForScreening
                                                                                          : kCascadeTauForPrecision;
}

std::string MatcherTypeToString(MatcherType type) {
  switch (type) {
    case MatcherType::kCascade:
      return "cascade";
    case MatcherType::kBruteForce:
      return "bruteforce";
    case MatcherType::kAuto:
      return "auto";
  }
  return "unknown";
}

bool MatcherTypeFromString(const std::string& name, MatcherType* type) {
  if (name == "cascade") {
    *type = MatcherType::kCascade;
    return true;
  }
  if (name == "bruteforce") {
    *type = MatcherType::kBruteForce;
    return true;
  }
  if (name == "auto") {
    *type = MatcherType::kAuto;
    return true;
  }
  return false;
}

}  // namespace cashash
