// --CasHash.matcher auto is decided from the run's data, one rule per
// device, and options the user typed are kept.
#include "cashash/matching/matcher_choice.h"

#include <gtest/gtest.h>

namespace cashash {
namespace {

CasHashOptions RunDefaults() {
  CasHashOptions options;
  options.matcher = MatcherType::kAuto;
  options.exact_rematch_min_matches = 12;
  return options;
}

struct Row {
  const char* name;
  MatcherType matcher;
  bool on_gpu;
  bool rematch_from_rule;
  bool guided;
  int given_min, given_max;
  // Expected:
  MatcherType chosen;
  int min_matches, max_matches;
};

TEST(ChooseAutoMatcher, OneRulePerDeviceAndTypedOptionsWin) {
  const Row rows[] = {
      {"CPU default", MatcherType::kAuto, false, true, false, 12, 0, MatcherType::kCascade, kCpuRematchWindowMin,
       kCpuRematchWindowMax},
      {"GPU default", MatcherType::kAuto, true, true, false, 12, 0, MatcherType::kCascade, 12, 0},
      {"CPU, threshold typed", MatcherType::kAuto, false, false, false, 20, 0, MatcherType::kCascade, 20, 0},
      {"CPU, rematch off typed", MatcherType::kAuto, false, false, false, 0, 0, MatcherType::kCascade, 0, 0},
      {"CPU, window typed", MatcherType::kAuto, false, false, false, 10, 40, MatcherType::kCascade, 10, 40},
      {"GPU, window typed", MatcherType::kAuto, true, false, false, 10, 40, MatcherType::kCascade, 10, 40},
      {"CPU, guided", MatcherType::kAuto, false, true, true, 12, 0, MatcherType::kCascade, 12, 0},
      {"CPU, cascade named: auto's window", MatcherType::kCascade, false, true, false, 12, 0, MatcherType::kCascade,
       kCpuRematchWindowMin, kCpuRematchWindowMax},
      {"GPU, cascade named", MatcherType::kCascade, true, true, false, 12, 0, MatcherType::kCascade, 12, 0},
      {"CPU, brute force named", MatcherType::kBruteForce, false, true, false, 12, 0, MatcherType::kBruteForce, 12,
       0},
  };
  for (const Row& row : rows) {
    CasHashOptions options = RunDefaults();
    options.matcher = row.matcher;
    options.exact_rematch_min_matches = row.given_min;
    options.exact_rematch_max_matches = row.given_max;
    MatcherChoiceInput input;
    input.on_gpu = row.on_gpu;
    input.features_per_image = 12000;
    input.rematch_from_rule = row.rematch_from_rule;
    input.guided = row.guided;
    const MatcherChoice choice = ChooseAutoMatcher(options, input);
    EXPECT_EQ(choice.matcher, row.chosen) << row.name;
    EXPECT_EQ(choice.exact_rematch_min_matches, row.min_matches) << row.name;
    EXPECT_EQ(choice.exact_rematch_max_matches, row.max_matches) << row.name;
    EXPECT_FALSE(choice.reason.empty()) << row.name;
    const CasHashOptions applied = ApplyMatcherChoice(options, choice);
    EXPECT_NE(applied.matcher, MatcherType::kAuto) << row.name;
    EXPECT_EQ(applied.Check(), "") << row.name;
  }
}

// The choice depends on nothing but its inputs: no clock, no load.
TEST(ChooseAutoMatcher, TheSameInputsGiveTheSameChoice) {
  MatcherChoiceInput input;
  input.features_per_image = 4096;
  const MatcherChoice first = ChooseAutoMatcher(RunDefaults(), input);
  for (int i = 0; i < 100; ++i) {
    const MatcherChoice again = ChooseAutoMatcher(RunDefaults(), input);
    EXPECT_EQ(again.matcher, first.matcher);
    EXPECT_EQ(again.exact_rematch_min_matches, first.exact_rematch_min_matches);
    EXPECT_EQ(again.exact_rematch_max_matches, first.exact_rematch_max_matches);
    EXPECT_EQ(again.reason, first.reason);
  }
  EXPECT_EQ(first.reason, "cascade, exact rematch of pairs with " + std::to_string(kCpuRematchWindowMin) + " to " +
                              std::to_string(kCpuRematchWindowMax - 1) + " cascade matches (CPU rule)");
}

// A window keeps the cascade's matches above it: tables and tau are then
// chosen for the cascade's own matches.
TEST(ChooseAutoMatcher, AWindowKeepsTheCascadesTauForPrecision) {
  EXPECT_TRUE(CascadeOnlyScreens(12, false));
  EXPECT_FALSE(CascadeOnlyScreens(12, false, 64));
  EXPECT_EQ(ChooseCascadeTau(12, false, 64), kCascadeTauForPrecision);
  EXPECT_EQ(ChooseCascadeTau(12, false), kCascadeTauForScreening);
  CasHashOptions options;
  options.exact_rematch_min_matches = 12;
  options.exact_rematch_max_matches = 12;
  EXPECT_NE(options.Check().find("CasHash.exact_rematch_max_matches"), std::string::npos);
  options.exact_rematch_max_matches = -1;
  EXPECT_NE(options.Check().find("CasHash.exact_rematch_max_matches"), std::string::npos);
}

}  // namespace
}  // namespace cashash
