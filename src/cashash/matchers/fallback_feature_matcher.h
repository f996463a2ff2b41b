// A backend that runs a primary backend (the GPU) and, the first time it
// fails with an error the caller calls recoverable (device memory
// exhausted), moves every added image to a fallback backend (the CPU), says
// so through `warn`, and goes on there: a run that outgrows the card
// finishes slower instead of failing. Other errors propagate unchanged.
// Every call of both interfaces goes through the same guard, exact matching
// included; an exact matcher already handed out (HoldForExact) belongs to
// the backend that made it, and its caller handles its errors
// (pipeline/exact_rematch_stage.h).
#pragma once

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

#include "cashash/matchers/exact_matcher.h"

namespace cashash {

// The traits (name, guidance) are the primary's: a fallback keeps them.
std::unique_ptr<MatchingBackend> CreateFallbackFeatureMatcher(
    std::unique_ptr<MatchingBackend> primary, std::function<std::unique_ptr<MatchingBackend>()> make_fallback,
    std::function<bool(const std::exception&)> recoverable, std::function<void(const std::string&)> warn);

// True for the GPU backend's out-of-memory and memory-budget errors: a
// DeviceMemoryError (cashash/base/device_memory_error.h), whatever its text.
bool IsDeviceMemoryError(const std::exception& error);

}  // namespace cashash
