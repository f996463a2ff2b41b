// Which devices a build can serve (no GPU needed): the parsing of CMake's
// architecture lists, the SASS and PTX compatibility rule, and the one-line
// message for a device the build cannot serve.
#include "cashash_cuda/utils/architecture_support.h"

#include <gtest/gtest.h>

#include <string>
#include <utility>
#include <vector>

namespace cashash {
namespace cuda {
namespace {

TEST(ArchitectureSupport, ParsesCMakeLists) {
  const CudaArchitectures portable = ParseCudaArchitectures("75-real;80-real;86-real;89-real;90");
  EXPECT_EQ(portable.sass, (std::vector<int>{75, 80, 86, 89, 90}));
  EXPECT_EQ(portable.ptx, (std::vector<int>{90}));
  const CudaArchitectures ptx_only = ParseCudaArchitectures("75-virtual");
  EXPECT_TRUE(ptx_only.sass.empty());
  EXPECT_EQ(ptx_only.ptx, (std::vector<int>{75}));
  // Commas as the build records it; an arch-specific target reads as its number.
  const CudaArchitectures listed = ParseCudaArchitectures("90a-real,80-real");
  EXPECT_EQ(listed.sass, (std::vector<int>{80, 90}));
  EXPECT_TRUE(listed.ptx.empty());
  const CudaArchitectures unknown = ParseCudaArchitectures("native");
  EXPECT_TRUE(unknown.sass.empty() && unknown.ptx.empty());
}

TEST(ArchitectureSupport, SassRunsWithinItsMajorVersionPtxOnEveryNewerDevice) {
  const CudaArchitectures sm80 = ParseCudaArchitectures("80-real");
  EXPECT_TRUE(CanRunOnDevice(sm80, 8, 0));
  EXPECT_TRUE(CanRunOnDevice(sm80, 8, 6));   // RTX 30
  EXPECT_TRUE(CanRunOnDevice(sm80, 8, 9));   // RTX 40
  EXPECT_FALSE(CanRunOnDevice(sm80, 9, 0));  // H100: no SASS of 9.x, no PTX
  EXPECT_FALSE(CanRunOnDevice(sm80, 7, 5));  // T4

  const CudaArchitectures sm86 = ParseCudaArchitectures("86-real");
  EXPECT_FALSE(CanRunOnDevice(sm86, 8, 0));  // A100 is older than 8.6

  const CudaArchitectures ptx75 = ParseCudaArchitectures("75-virtual");
  EXPECT_TRUE(CanRunOnDevice(ptx75, 7, 5));
  EXPECT_TRUE(CanRunOnDevice(ptx75, 9, 0));
  EXPECT_TRUE(CanRunOnDevice(ptx75, 12, 0));  // Blackwell compiles the PTX
  EXPECT_FALSE(CanRunOnDevice(ptx75, 7, 0));

  const CudaArchitectures portable = ParseCudaArchitectures("75-real;80-real;86-real;89-real;90");
  for (const auto& cc : std::vector<std::pair<int, int>>{{7, 5}, {8, 0}, {8, 6}, {8, 7}, {8, 9}, {9, 0}, {10, 0},
                                                         {12, 0}}) {
    EXPECT_TRUE(CanRunOnDevice(portable, cc.first, cc.second)) << cc.first << "." << cc.second;
  }
  EXPECT_FALSE(CanRunOnDevice(portable, 7, 0));  // V100
  EXPECT_FALSE(CanRunOnDevice(portable, 6, 1));

  // Nothing recorded (an unresolved keyword): the driver's probe decides.
  EXPECT_TRUE(CanRunOnDevice(CudaArchitectures{}, 9, 0));
}

TEST(ArchitectureSupport, DescribesSassAndPtx) {
  EXPECT_EQ(DescribeCudaArchitectures(ParseCudaArchitectures("75-real;80-real;86-real;89-real;90")),
            "SASS sm_75 sm_80 sm_86 sm_89 sm_90, PTX compute_90");
  EXPECT_EQ(DescribeCudaArchitectures(ParseCudaArchitectures("80-real")), "SASS sm_80, no PTX");
  EXPECT_EQ(DescribeCudaArchitectures(ParseCudaArchitectures("75-virtual")), "PTX compute_75");
  EXPECT_EQ(DescribeCudaArchitectures(CudaArchitectures{}), "none");
}

TEST(ArchitectureSupport, MessageNamesTheGpuItsCapabilityTheBuildAndTheFlag) {
  const std::string message =
      UnservableDeviceMessage(0, "NVIDIA H100 80GB HBM3", 9, 0, ParseCudaArchitectures("80-real"));
  EXPECT_EQ(message.find('\n'), std::string::npos) << "one line";
  EXPECT_NE(message.find("GPU 0"), std::string::npos) << message;
  EXPECT_NE(message.find("NVIDIA H100 80GB HBM3"), std::string::npos) << message;
  EXPECT_NE(message.find("compute capability 9.0"), std::string::npos) << message;
  EXPECT_NE(message.find("SASS sm_80, no PTX"), std::string::npos) << message;
  EXPECT_NE(message.find("-DCASHASH_CUDA_ARCHITECTURES=90"), std::string::npos) << message;

  const std::string old_card = UnservableDeviceMessage(1, "Tesla V100-SXM2-16GB", 7, 0,
                                                       ParseCudaArchitectures("75-real;80-real;86-real;89-real;90"));
  EXPECT_NE(old_card.find("compute capability 7.0"), std::string::npos) << old_card;
  EXPECT_NE(old_card.find("7.5 or newer"), std::string::npos) << old_card;
}

TEST(ArchitectureSupport, ThisBuildRecordsWhatItCarries) {
  const CudaArchitectures& compiled = CompiledCudaArchitectures();
  EXPECT_FALSE(compiled.sass.empty() && compiled.ptx.empty()) << "the build recorded no CUDA architectures";
}

}  // namespace
}  // namespace cuda
}  // namespace cashash
