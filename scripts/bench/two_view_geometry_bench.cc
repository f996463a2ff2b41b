// Times EstimateTwoViewGeometry on correspondences read from a text file, so
// the same pairs can be fed to pycolmap for comparison
// (scripts/compare_two_view_geometry.py writes the files and runs both).
//
// File format: "width height focal has_prior", then "n", then n lines
// "x1 y1 x2 y2" (pixels; match i pairs point i of each image).
// Usage: two_view_geometry_bench FILE [repeats] [seed]
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <vector>

#include "cashash/geometry/two_view_geometry.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: " << argv[0] << " FILE [repeats] [seed]\n";
    return 2;
  }
  std::ifstream in(argv[1]);
  const int repeats = argc > 2 ? std::atoi(argv[2]) : 10;
  double width, height, focal;
  int has_prior;
  size_t n;
  if (!(in >> width >> height >> focal >> has_prior >> n)) {
    std::cerr << "cannot read " << argv[1] << "\n";
    return 1;
  }
  cashash::Camera camera;
  camera.model_id = 0;  // SIMPLE_PINHOLE
  camera.width = static_cast<uint64_t>(width);
  camera.height = static_cast<uint64_t>(height);
  camera.params = {focal, width / 2, height / 2};
  camera.has_prior_focal_length = has_prior != 0;
  std::vector<Eigen::Vector2d> points1(n), points2(n);
  cashash::FeatureMatches matches(n);
  for (size_t i = 0; i < n; ++i) {
    in >> points1[i].x() >> points1[i].y() >> points2[i].x() >> points2[i].y();
    matches[i].point2D_idx1 = matches[i].point2D_idx2 = static_cast<cashash::point2D_t>(i);
  }
  cashash::TwoViewGeometryOptions options;
  options.random_seed = argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 0;
  cashash::TwoViewGeometry geometry;
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r) {
    options.random_seed += 1;  // a different sample stream per repeat, as per pair
    const auto start = std::chrono::steady_clock::now();
    geometry = cashash::EstimateTwoViewGeometry(camera, points1, camera, points2, matches, options);
    times.push_back(
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
  }
  double total = 0;
  for (double t : times) total += t;
  std::printf("ms_mean %.3f config %d inliers %zu\n", total / repeats, geometry.config,
              geometry.inlier_matches.size());
  return 0;
}
