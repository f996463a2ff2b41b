#include "cashash_cuda/utils/architecture_support.h"

#include <algorithm>
#include <cctype>
#include <sstream>

// CMake defines CASHASH_CUDA_ARCHITECTURES_BUILT as the resolved
// CUDA_ARCHITECTURES of the backend (cmake/cashashCudaArchitectures.cmake).
#ifndef CASHASH_CUDA_ARCHITECTURES_BUILT
#define CASHASH_CUDA_ARCHITECTURES_BUILT ""
#endif

namespace cashash {
namespace cuda {
namespace {

void AddUnique(std::vector<int>* list, int value) {
  if (std::find(list->begin(), list->end(), value) == list->end()) list->push_back(value);
}

}  // namespace

CudaArchitectures ParseCudaArchitectures(const std::string& cmake_list) {
  CudaArchitectures result;
  std::string list = cmake_list;
  std::replace(list.begin(), list.end(), ',', ';');
  std::stringstream items(list);
  std::string item;
  while (std::getline(items, item, ';')) {
    size_t digits = 0;
    while (digits < item.size() && std::isdigit(static_cast<unsigned char>(item[digits]))) ++digits;
    if (digits == 0) continue;
    const int number = std::stoi(item.substr(0, digits));
    const bool real = item.find("-real") != std::string::npos;
    const bool virtual_only = item.find("-virtual") != std::string::npos;
    if (!virtual_only) AddUnique(&result.sass, number);
    if (!real) AddUnique(&result.ptx, number);
  }
  std::sort(result.sass.begin(), result.sass.end());
  std::sort(result.ptx.begin(), result.ptx.end());
  return result;
}

const CudaArchitectures& CompiledCudaArchitectures() {
  static const CudaArchitectures compiled = ParseCudaArchitectures(CASHASH_CUDA_ARCHITECTURES_BUILT);
  return compiled;
}

std::string DescribeCudaArchitectures(const CudaArchitectures& architectures) {
  if (architectures.sass.empty() && architectures.ptx.empty()) return "none";
  std::string text;
  if (!architectures.sass.empty()) {
    text += "SASS";
    for (const int a : architectures.sass) text += " sm_" + std::to_string(a);
  }
  if (!architectures.ptx.empty()) {
    text += std::string(text.empty() ? "" : ", ") + "PTX";
    for (const int a : architectures.ptx) text += " compute_" + std::to_string(a);
  } else {
    text += ", no PTX";
  }
  return text;
}

bool CanRunOnDevice(const CudaArchitectures& architectures, int major, int minor) {
  if (architectures.sass.empty() && architectures.ptx.empty()) return true;
  const int capability = 10 * major + minor;
  for (const int a : architectures.sass) {
    if (a / 10 == major && a <= capability) return true;
  }
  for (const int a : architectures.ptx) {
    if (a <= capability) return true;
  }
  return false;
}

std::string UnservableDeviceMessage(int gpu_index, const std::string& gpu_name, int major, int minor,
                                    const CudaArchitectures& architectures) {
  const std::string capability = std::to_string(major) + "." + std::to_string(minor);
  const std::string arch = std::to_string(10 * major + minor);
  const std::string head = "GPU " + std::to_string(gpu_index) + " (" + gpu_name + ", compute capability " +
                           capability + ") cannot run this build's GPU code (" +
                           DescribeCudaArchitectures(architectures) + ")";
  // The kernels use ldmatrix and the int8 mma, which start at 7.5.
  if (10 * major + minor < 75) return head + "; cashash's GPU backend needs compute capability 7.5 or newer";
  return head + "; rebuild with -DCASHASH_CUDA_ARCHITECTURES=" + arch + " to use it";
}

}  // namespace cuda
}  // namespace cashash
