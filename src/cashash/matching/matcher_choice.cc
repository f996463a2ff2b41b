#include "cashash/matching/matcher_choice.h"

namespace cashash {
namespace {

std::string DescribeRematch(int min_matches, int max_matches) {
  if (min_matches <= 0) return "the cascade's own matches";
  if (max_matches <= 0) return "exact rematch of pairs with at least " + std::to_string(min_matches) + " cascade matches";
  return "exact rematch of pairs with " + std::to_string(min_matches) + " to " + std::to_string(max_matches - 1) +
         " cascade matches";
}

}  // namespace

MatcherChoice ChooseAutoMatcher(const CasHashOptions& options, const MatcherChoiceInput& input) {
  MatcherChoice choice;
  choice.matcher = options.matcher;
  choice.exact_rematch_min_matches = options.exact_rematch_min_matches;
  choice.exact_rematch_max_matches = options.exact_rematch_max_matches;
  if (options.matcher == MatcherType::kBruteForce) {
    choice.reason = MatcherTypeToString(options.matcher) + " (as set by the options)";
    return choice;
  }
  // The cascade named is the cascade auto chooses, with the same rematch
  // rule: the name picks the algorithm, not another screen.
  choice.matcher = MatcherType::kCascade;
  if (input.guided) {
    choice.reason = "cascade (guided matching needs it)";
    return choice;
  }
  if (!input.on_gpu && input.rematch_from_rule && options.exact_rematch_min_matches > 0) {
    choice.exact_rematch_min_matches = kCpuRematchWindowMin;
    choice.exact_rematch_max_matches = kCpuRematchWindowMax;
  }
  const std::string rule = input.rematch_from_rule ? (input.on_gpu ? "GPU rule" : "CPU rule") : "rematch as set";
  choice.reason =
      "cascade, " + DescribeRematch(choice.exact_rematch_min_matches, choice.exact_rematch_max_matches) + " (" + rule + ")";
  return choice;
}

CasHashOptions ApplyMatcherChoice(const CasHashOptions& options, const MatcherChoice& choice) {
  CasHashOptions applied = options;
  applied.matcher = choice.matcher;
  applied.exact_rematch_min_matches = choice.exact_rematch_min_matches;
  applied.exact_rematch_max_matches = choice.exact_rematch_max_matches;
  return applied;
}

}  // namespace cashash
