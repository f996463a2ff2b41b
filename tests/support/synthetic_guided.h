// Two views of a synthetic scene for the guided-matching tests: image 2
// holds a perturbed copy of every feature of image 1 at its true position
// (known F), and, for every third feature, a decoy: a copy at least as close
// in descriptor space placed far from the feature's epipolar line. Exhaustive
// matching loses those features (the ratio test sees two equally good
// candidates, or picks the decoy); guided matching only sees the true one.
#pragma once

#include <algorithm>
#include <array>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "cashash/matching/epipolar_band.h"
#include "cashash/base/types.h"
#include "ordered_draws.h"
#include "synthetic_sift.h"
#include "synthetic_two_view.h"

namespace cashash {
namespace testing_support {

struct GuidedScene {
  ImageFeatures image1, image2;
  std::vector<int> truth;  // image-2 row of the true match of image-1 row i
  std::vector<int> decoy;  // image-2 row of its decoy, or -1
  std::array<double, 9> F{};  // true F, row-major
  std::vector<float> xy1, xy2;  // interleaved keypoint pixels
};

inline Keypoint MakeKeypoint(const Eigen::Vector2d& p, float scale) {
  Keypoint k;
  k.x = static_cast<float>(p.x());
  k.y = static_cast<float>(p.y());
  k.a11 = scale;
  k.a12 = 0.f;
  k.a21 = 0.f;
  k.a22 = scale;
  return k;
}

// One row of image 2 before shuffling: a perturbed copy of an image-1
// feature (source, -1 for none), a decoy or the true match.
struct GuidedRow {
  std::vector<uint8_t> desc;
  Keypoint kp;
  int source;
  bool decoy;
};

inline std::vector<uint8_t> PerturbedDescriptor(std::vector<uint8_t> d, std::mt19937* rng) {
  std::uniform_int_distribution<int> noise(-6, 6);
  for (uint8_t& x : d) x = static_cast<uint8_t>(std::clamp(int(x) + noise(*rng), 0, 255));
  return d;
}

inline double UnitDraw(std::mt19937* rng) { return std::uniform_real_distribution<double>(0.0, 1.0)(*rng); }

// A point of the image at least 40 px off `line`.
inline Eigen::Vector2d PointOffLine(const EpipolarLine& line, const SyntheticScene& scene, std::mt19937* rng) {
  Eigen::Vector2d p;
  do {
    // y is drawn first, as the first version drew it (it left the order to
    // the compiler), so that the tests' scenes stay the same.
    const double y = UnitDraw(rng) * scene.height;
    p = Eigen::Vector2d(UnitDraw(rng) * scene.width, y);
  } while (line.Contains(static_cast<float>(p.x()), static_cast<float>(p.y()), 40.0));
  return p;
}

// Both generators: image 1 gets a random SIFT descriptor and scale per
// point of a synthetic two-view scene; add_rows(i, descriptor, scale,
// epipolar line of point i in image 2, rng, &rows) puts image 2's rows for
// feature i; then the rows are shuffled, truth and decoy filled by source,
// and the positions interleaved.
template <typename AddRows>
GuidedScene GenerateGuidedScene(int num_features, unsigned seed, unsigned stream, AddRows add_rows) {
  SceneOptions options;
  options.num_inliers = num_features;
  options.outlier_ratio = 0;
  options.noise_px = 0.3;
  options.seed = seed;
  const SyntheticScene scene = MakeScene(options);
  GuidedScene g;
  const Eigen::Matrix3d F = scene.TrueF();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) g.F[3 * r + c] = F(r, c);
  std::mt19937 rng(seed * 7919u + stream);
  std::uniform_real_distribution<float> scale(1.0f, 8.0f);
  const int n = static_cast<int>(scene.points1.size());
  std::vector<GuidedRow> rows2;
  for (int i = 0; i < n; ++i) {
    const std::vector<uint8_t> d = RandomSift(&rng);
    const float s = scale(rng);
    const Eigen::Vector2d& p1 = scene.points1[i];
    g.image1.keypoints.push_back(MakeKeypoint(p1, s));
    g.image1.descriptors.data.insert(g.image1.descriptors.data.end(), d.begin(), d.end());
    const EpipolarLine line = LineInSecondImage(g.F.data(), static_cast<float>(p1.x()), static_cast<float>(p1.y()));
    add_rows(scene, i, d, s, line, &rng, &rows2);
  }
  std::shuffle(rows2.begin(), rows2.end(), rng);
  g.truth.assign(n, -1);
  g.decoy.assign(n, -1);
  for (size_t r = 0; r < rows2.size(); ++r) {
    g.image2.keypoints.push_back(rows2[r].kp);
    g.image2.descriptors.data.insert(g.image2.descriptors.data.end(), rows2[r].desc.begin(), rows2[r].desc.end());
    if (rows2[r].source >= 0) (rows2[r].decoy ? g.decoy : g.truth)[rows2[r].source] = static_cast<int>(r);
  }
  for (const Keypoint& k : g.image1.keypoints) {
    g.xy1.push_back(k.x);
    g.xy1.push_back(k.y);
  }
  for (const Keypoint& k : g.image2.keypoints) {
    g.xy2.push_back(k.x);
    g.xy2.push_back(k.y);
  }
  return g;
}

inline GuidedScene MakeGuidedScene(int num_features, unsigned seed) {
  return GenerateGuidedScene(num_features, seed, 1,
                             [](const SyntheticScene& scene, int i, const std::vector<uint8_t>& d, float s,
                                const EpipolarLine& line, std::mt19937* rng, std::vector<GuidedRow>* rows) {
                               rows->push_back(GuidedRow{PerturbedDescriptor(d, rng),
                                                         MakeKeypoint(scene.points2[i], 1.1f * s), i, false});
                               if (i % 3 != 0) return;
                               // A decoy at least 40 px off the feature's epipolar line.
                               const Eigen::Vector2d p = PointOffLine(line, scene, rng);
                               rows->push_back(GuidedRow{PerturbedDescriptor(d, rng), MakeKeypoint(p, 1.1f * s), i, true});
                             });
}

// Repeated structure along the epipolar line: as MakeGuidedScene, but for
// every third feature of image 1 the true match is missing from image 2
// (occluded), and two copies of it stand elsewhere, with one descriptor
// (the same element repeated): one on the feature's epipolar line (within
// 0.5 px of it, 40 to 200 px from where the true match would be), the other
// at least 40 px off the line. Within the band only the copy on the line
// competes, so a ratio test among band candidates accepts it; in the whole
// image the two copies are equally good rivals. truth is -1 for those
// features, decoy the row of the copy on the line.
inline GuidedScene MakeRepeatedStructureScene(int num_features, unsigned seed) {
  return GenerateGuidedScene(
      num_features, seed, 3,
      [](const SyntheticScene& scene, int i, const std::vector<uint8_t>& d, float s, const EpipolarLine& line,
         std::mt19937* rng, std::vector<GuidedRow>* rows) {
        if (i % 3 != 0) {
          rows->push_back(GuidedRow{PerturbedDescriptor(d, rng), MakeKeypoint(scene.points2[i], 1.1f * s), i, false});
          return;
        }
        // Along the line: direction (-b, a) from the true position.
        const double length = 40.0 + 160.0 * UnitDraw(rng);
        const double t = length * (UnitDraw(rng) < 0.5 ? -1.0 : 1.0);
        const Eigen::Vector2d on_line = scene.points2[i] + t * Eigen::Vector2d(-line.b, line.a);
        const std::vector<uint8_t> copy = PerturbedDescriptor(d, rng);
        rows->push_back(GuidedRow{copy, MakeKeypoint(on_line, 1.1f * s), i, true});
        rows->push_back(GuidedRow{copy, MakeKeypoint(PointOffLine(line, scene, rng), 1.1f * s), -1, false});
      });
}

// An image that shares nothing with the others.
inline ImageFeatures MakeUnrelatedImage(int num_features, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::uniform_real_distribution<float> scale(1.0f, 8.0f);
  ImageFeatures image;
  for (int i = 0; i < num_features; ++i) {
    const std::vector<uint8_t> d = RandomSift(&rng);
    image.descriptors.data.insert(image.descriptors.data.end(), d.begin(), d.end());
    // The scale, then y, then x (ordered_draws.h).
    const float s = scale(rng);
    const auto u = DrawLastFirst<2>([&] { return unit(rng); });
    image.keypoints.push_back(MakeKeypoint(Eigen::Vector2d(u[0] * 1280, u[1] * 960), s));
  }
  return image;
}

}  // namespace testing_support
}  // namespace cashash
