// cashash: Cascade Hashing feature matching for COLMAP databases. The
// executable's entry point; the libraries it links never read the process
// environment.
#include <cstdlib>
#include <iostream>
#include <string>

#include "colmap_bridge/api/build_info.h"
#include "colmap_bridge/commands/matching_commands.h"
#include "colmap_bridge/commands/verify_command.h"
#include "synthetic/generate_database_command.h"
#ifdef CASHASH_WITH_MPI
#include "distributed/mpi_process_group.h"
#endif

namespace {

#ifdef CASHASH_WITH_MPI
// Whether an MPI launcher started this process: Open MPI's mpirun, MPICH /
// Intel MPI (Hydra) and PMIx launchers (srun) set these. This is how a
// process learns it was launched, not configuration; asking MPI instead
// would start it in every run (an MPI singleton: 0.3-0.4 s with Open MPI
// 4.1), so the question is answered here, once, and handed to the group.
cashash::distributed::ProcessLaunch HowThisProcessWasLaunched() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "MPI_LOCALNRANKS"}) {
    if (std::getenv(name) != nullptr) return cashash::distributed::ProcessLaunch::kMpiLauncher;
  }
  return cashash::distributed::ProcessLaunch::kStandalone;
}
#endif

void PrintUsage() {
  std::cout << "cashash -- Cascade Hashing feature matching for COLMAP databases\n\n"
               "Usage:\n"
               "  cashash exhaustive_matcher --database_path DB [options]\n"
               "  cashash guided_matcher --database_path DB [options]   (two-stage Ga-CasHash, all pairs)\n"
               "  cashash retrieval_matcher --database_path DB [--VocabTreeMatching.num_images 100] [options]\n"
               "      (also as vocab_tree_matcher: pairs from visual words of the hash codes, no tree)\n"
               "  cashash sequential_matcher --database_path DB [--SequentialMatching.overlap 10 ...]\n"
               "  cashash spatial_matcher --database_path DB [--SpatialMatching.max_distance 100 ...]\n"
               "  cashash matches_importer --database_path DB --match_list_path PAIRS.txt --match_type pairs\n"
               "  cashash geometric_verifier --database_path DB   (verifies the stored matches only)\n"
               "  cashash generate_database --database_path NEW.db --source_database_path REAL.db --num_images N\n"
               "  cashash --version   (version and the CUDA architectures this build carries)\n\n"
               "Run 'cashash COMMAND --help' for the options of a command (COLMAP's option names\n"
               "of 3.8 and 4.x are accepted, plus --CasHash.*)."
            << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
#ifdef CASHASH_WITH_MPI
  // Only the executable links MPI; the library sees it through this group.
  cashash::distributed::InstallProcessGroup(cashash::distributed::CreateMpiProcessGroup(HowThisProcessWasLaunched()));
#endif
  if (argc < 2 || std::string(argv[1]) == "-h" || std::string(argv[1]) == "--help" ||
      std::string(argv[1]) == "help") {
    PrintUsage();
    return argc < 2 ? EXIT_FAILURE : EXIT_SUCCESS;
  }
  const std::string command = argv[1];
  if (command == "--version" || command == "version") {
    std::cout << cashash::colmap::BuildInfoLine() << std::endl;
    return EXIT_SUCCESS;
  }
  if (command == "exhaustive_matcher") return cashash::colmap::RunExhaustiveMatcher(argc - 1, argv + 1);
  if (command == "guided_matcher") return cashash::colmap::RunGuidedMatcher(argc - 1, argv + 1);
  if (command == "retrieval_matcher" || command == "vocab_tree_matcher") {
    return cashash::colmap::RunRetrievalMatcher(command, argc - 1, argv + 1);
  }
  if (command == "sequential_matcher") return cashash::colmap::RunSequentialMatcher(argc - 1, argv + 1);
  if (command == "spatial_matcher") return cashash::colmap::RunSpatialMatcher(argc - 1, argv + 1);
  if (command == "matches_importer") return cashash::colmap::RunMatchesImporter(argc - 1, argv + 1);
  if (command == "geometric_verifier") return cashash::colmap::RunGeometricVerifier(argc - 1, argv + 1);
  if (command == "generate_database") return cashash::colmap::RunGenerateDatabase(argc - 1, argv + 1);
  std::cerr << "ERROR: unknown command '" << command << "'" << std::endl;
  PrintUsage();
  return EXIT_FAILURE;
}
