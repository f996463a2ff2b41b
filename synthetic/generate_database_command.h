// `cashash generate_database`: writes a large synthetic COLMAP database with
// real SIFT descriptors (see database_generator.h). Returns the exit code.
#pragma once

namespace cashash {
namespace colmap {

int RunGenerateDatabase(int argc, const char* const* argv);

}  // namespace colmap
}  // namespace cashash
