#include "cashash/geometry/camera_models.h"

#include <gtest/gtest.h>

#include <cmath>
#include <utility>
#include <vector>

#include "cashash/geometry/camera_projection.h"

namespace cashash {
namespace {

Camera MakeCamera(int model_id, std::vector<double> params) {
  Camera c;
  c.model_id = model_id;
  c.width = 1600;
  c.height = 1200;
  c.params = std::move(params);
  c.has_prior_focal_length = true;
  return c;
}

TEST(CameraModels, NamesAndParameterCounts) {
  const char* names[] = {"SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL",
                         "OPENCV", "OPENCV_FISHEYE", "FULL_OPENCV", "FOV",
                         "SIMPLE_RADIAL_FISHEYE", "RADIAL_FISHEYE", "THIN_PRISM_FISHEYE"};
  const int counts[] = {3, 4, 4, 5, 8, 8, 12, 5, 4, 5, 12};
  for (int id = 0; id <= 10; ++id) {
    EXPECT_EQ(CameraModelIdToName(id), names[id]);
    EXPECT_EQ(CameraModelNumParams(id), counts[id]);
  }
  EXPECT_EQ(CameraModelIdToName(11), "");
  EXPECT_EQ(CameraModelIdToName(-1), "");
  EXPECT_EQ(CameraModelNumParams(42), -1);
  for (int id : {0, 1, 2, 3, 4, 6}) EXPECT_TRUE(CameraModelIsSupported(id)) << id;
  EXPECT_FALSE(CameraModelIsSupported(7));
  EXPECT_FALSE(CameraModelIsSupported(10));
  EXPECT_FALSE(CameraModelIsSupported(99));
}

TEST(CameraModels, MeanFocalLength) {
  EXPECT_DOUBLE_EQ(CameraMeanFocalLength(MakeCamera(0, {1200, 800, 600})), 1200);
  EXPECT_DOUBLE_EQ(CameraMeanFocalLength(MakeCamera(1, {1000, 1100, 800, 600})), 1050);
  EXPECT_DOUBLE_EQ(CameraMeanFocalLength(MakeCamera(2, {900, 800, 600, 0.1})), 900);
}

TEST(CameraModels, PinholeImageToWorld) {
  double u, v;
  CameraImageToWorld(MakeCamera(1, {1000, 500, 800, 600}), 1800, 100, &u, &v);
  EXPECT_DOUBLE_EQ(u, 1.0);
  EXPECT_DOUBLE_EQ(v, -1.0);
}

// Distort (u, v) into pixels and undistort back, over a grid spanning the
// image, for every model we support.
TEST(CameraModels, UndistortionRoundTrips) {
  const std::vector<Camera> cameras = {
      MakeCamera(0, {1200, 800, 600}),
      MakeCamera(1, {1200, 1150, 800, 600}),
      MakeCamera(2, {1200, 800, 600, -0.08}),
      MakeCamera(3, {1200, 800, 600, -0.1, 0.03}),
      MakeCamera(4, {1200, 1150, 800, 600, -0.1, 0.02, 0.001, -0.002}),
      MakeCamera(5, {700, 710, 800, 600, 0.05, -0.01, 0.002, -0.001}),
      MakeCamera(6, {1200, 1150, 800, 600, -0.1, 0.02, 0.001, -0.002, 0.001, 0.01, 0.002, 0.0005}),
      MakeCamera(8, {700, 800, 600, 0.04}),
      MakeCamera(9, {700, 800, 600, 0.04, -0.005}),
  };
  for (const Camera& camera : cameras) {
    for (double u = -0.6; u <= 0.6; u += 0.1) {
      for (double v = -0.45; v <= 0.45; v += 0.09) {
        double x, y, u2, v2;
        CameraWorldToImage(camera, u, v, &x, &y);
        CameraImageToWorld(camera, x, y, &u2, &v2);
        EXPECT_NEAR(u2, u, 1e-9) << CameraModelIdToName(camera.model_id);
        EXPECT_NEAR(v2, v, 1e-9) << CameraModelIdToName(camera.model_id);
      }
    }
  }
}

TEST(CameraModels, DistortionMovesPoints) {
  // A radial camera must not behave like a pinhole one.
  const Camera radial = MakeCamera(2, {1000, 800, 600, -0.2});
  double x, y;
  CameraWorldToImage(radial, 0.5, 0.0, &x, &y);
  EXPECT_NEAR(x, 800 + 1000 * 0.5 * (1 - 0.2 * 0.25), 1e-9);
  EXPECT_NEAR(y, 600, 1e-12);
}

// Polynomial lenses with every coefficient zero (feature_extractor's
// SIMPLE_RADIAL) are pinholes to the bit; zero fisheye coefficients still
// bend rays.
TEST(CameraModels, ZeroPolynomialDistortionIsExactlyPinhole) {
  const Camera simple_pinhole = MakeCamera(0, {1200, 800, 600});
  const Camera pinhole = MakeCamera(1, {1200, 1150, 800, 600});
  const std::vector<std::pair<Camera, const Camera*>> cases = {
      {MakeCamera(2, {1200, 800, 600, 0}), &simple_pinhole},
      {MakeCamera(3, {1200, 800, 600, 0, 0}), &simple_pinhole},
      {MakeCamera(4, {1200, 1150, 800, 600, 0, 0, 0, 0}), &pinhole},
      {MakeCamera(6, {1200, 1150, 800, 600, 0, 0, 0, 0, 0, 0, 0, 0}), &pinhole},
  };
  for (const auto& [camera, reference] : cases) {
    for (double x = 3.5; x < 1600; x += 151.25) {
      for (double y = 1.25; y < 1200; y += 97.5) {
        double u, v, u_ref, v_ref;
        CameraImageToWorld(camera, x, y, &u, &v);
        CameraImageToWorld(*reference, x, y, &u_ref, &v_ref);
        EXPECT_EQ(u, u_ref) << CameraModelIdToName(camera.model_id);
        EXPECT_EQ(v, v_ref) << CameraModelIdToName(camera.model_id);
      }
    }
  }
  double u, v, u_ref, v_ref;
  CameraImageToWorld(MakeCamera(8, {1200, 800, 600, 0}), 1500, 1100, &u, &v);
  CameraImageToWorld(simple_pinhole, 1500, 1100, &u_ref, &v_ref);
  EXPECT_GT(std::abs(u - u_ref), 1e-3);
}

}  // namespace
}  // namespace cashash
