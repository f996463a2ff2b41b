// COLMAP's camera models: parameter layouts, distortion functions, and
// Newton-iteration undistortion (COLMAP inverts its distortion the same way,
// so normalised points agree with what COLMAP feeds its E estimator).
#include "cashash/geometry/camera_models.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Core>
#include <Eigen/LU>

#include "cashash/geometry/camera_projection.h"

namespace cashash {
namespace {

enum class Distortion {
  kNone,
  kSimpleRadial,
  kRadial,
  kOpenCV,
  kOpenCVFisheye,
  kFullOpenCV,
  kRadialFisheye,  // SIMPLE_RADIAL_FISHEYE and RADIAL_FISHEYE
  kUnsupported,
};

struct ModelInfo {
  const char* name;
  int num_params;
  bool single_focal;  // params start f, cx, cy; otherwise fx, fy, cx, cy
  Distortion distortion;
};

constexpr ModelInfo kModels[] = {
    {"SIMPLE_PINHOLE", 3, true, Distortion::kNone},
    {"PINHOLE", 4, false, Distortion::kNone},
    {"SIMPLE_RADIAL", 4, true, Distortion::kSimpleRadial},
    {"RADIAL", 5, true, Distortion::kRadial},
    {"OPENCV", 8, false, Distortion::kOpenCV},
    {"OPENCV_FISHEYE", 8, false, Distortion::kOpenCVFisheye},
    {"FULL_OPENCV", 12, false, Distortion::kFullOpenCV},
    {"FOV", 5, false, Distortion::kUnsupported},
    {"SIMPLE_RADIAL_FISHEYE", 4, true, Distortion::kRadialFisheye},
    {"RADIAL_FISHEYE", 5, true, Distortion::kRadialFisheye},
    {"THIN_PRISM_FISHEYE", 12, false, Distortion::kUnsupported},
};
constexpr int kNumModels = sizeof(kModels) / sizeof(kModels[0]);

const ModelInfo* Info(int model_id) {
  return model_id >= 0 && model_id < kNumModels ? &kModels[model_id] : nullptr;
}

// Pinhole part of a camera, with its distortion coefficients.
struct Intrinsics {
  double fx = 1, fy = 1, cx = 0, cy = 0;
  const double* extra = nullptr;
  int num_extra = 0;
  Distortion distortion = Distortion::kNone;
};

Intrinsics Unpack(const Camera& camera) {
  Intrinsics in;
  const ModelInfo* info = Info(camera.model_id);
  if (info == nullptr || static_cast<int>(camera.params.size()) < info->num_params) {
    in.distortion = Distortion::kUnsupported;
    return in;
  }
  const double* p = camera.params.data();
  if (info->single_focal) {
    in.fx = in.fy = p[0];
    in.cx = p[1];
    in.cy = p[2];
    in.extra = p + 3;
    in.num_extra = info->num_params - 3;
  } else {
    in.fx = p[0];
    in.fy = p[1];
    in.cx = p[2];
    in.cy = p[3];
    in.extra = p + 4;
    in.num_extra = info->num_params - 4;
  }
  in.distortion = info->distortion;
  // Polynomial models with every coefficient zero (SIMPLE_RADIAL as
  // feature_extractor leaves it) displace nothing: skipping Undistort's
  // Newton step then gives the same bits (its first step is exactly zero)
  // without its five Distort calls per point. Fisheye models with zero
  // coefficients still bend rays, so they keep theirs.
  const bool polynomial = in.distortion == Distortion::kSimpleRadial || in.distortion == Distortion::kRadial ||
                          in.distortion == Distortion::kOpenCV || in.distortion == Distortion::kFullOpenCV;
  if (polynomial && std::all_of(in.extra, in.extra + in.num_extra, [](double k) { return k == 0.0; })) {
    in.distortion = Distortion::kNone;
  }
  return in;
}

// Displacement (du, dv) that the model's lens adds to the ideal point (u, v).
void Distort(const Intrinsics& in, double u, double v, double* du, double* dv) {
  const double* k = in.extra;
  const double u2 = u * u, v2 = v * v, uv = u * v, r2 = u2 + v2;
  switch (in.distortion) {
    case Distortion::kSimpleRadial: {
      const double radial = k[0] * r2;
      *du = u * radial;
      *dv = v * radial;
      return;
    }
    case Distortion::kRadial: {
      const double radial = k[0] * r2 + k[1] * r2 * r2;
      *du = u * radial;
      *dv = v * radial;
      return;
    }
    case Distortion::kOpenCV: {
      const double radial = k[0] * r2 + k[1] * r2 * r2;
      *du = u * radial + 2 * k[2] * uv + k[3] * (r2 + 2 * u2);
      *dv = v * radial + 2 * k[3] * uv + k[2] * (r2 + 2 * v2);
      return;
    }
    case Distortion::kFullOpenCV: {
      const double r4 = r2 * r2, r6 = r4 * r2;
      const double radial =
          (1 + k[0] * r2 + k[1] * r4 + k[4] * r6) / (1 + k[5] * r2 + k[6] * r4 + k[7] * r6);
      *du = u * radial + 2 * k[2] * uv + k[3] * (r2 + 2 * u2) - u;
      *dv = v * radial + 2 * k[3] * uv + k[2] * (r2 + 2 * v2) - v;
      return;
    }
    case Distortion::kOpenCVFisheye:
    case Distortion::kRadialFisheye: {
      const double r = std::sqrt(r2);
      if (r < 1e-15) {
        *du = *dv = 0;
        return;
      }
      const double theta = std::atan(r);
      const double t2 = theta * theta;
      double poly = 1.0, t_pow = 1.0;
      for (int i = 0; i < in.num_extra; ++i) {
        t_pow *= t2;
        poly += k[i] * t_pow;
      }
      const double factor = theta * poly / r;
      *du = u * factor - u;
      *dv = v * factor - v;
      return;
    }
    case Distortion::kNone:
    case Distortion::kUnsupported:
      break;
  }
  *du = *dv = 0;
}

// Solves p + d(p) = target for p by Newton's method with a central-difference
// Jacobian.
void Undistort(const Intrinsics& in, double* u, double* v) {
  if (in.distortion == Distortion::kNone || in.distortion == Distortion::kUnsupported) return;
  constexpr int kMaxIterations = 100;
  constexpr double kMinStepSquared = 1e-20;
  constexpr double kRelativeStep = 1e-6;
  const Eigen::Vector2d target(*u, *v);
  Eigen::Vector2d p = target;
  for (int it = 0; it < kMaxIterations; ++it) {
    const double h0 = std::max(1e-12, std::fabs(kRelativeStep * p(0)));
    const double h1 = std::max(1e-12, std::fabs(kRelativeStep * p(1)));
    Eigen::Vector2d d, d0f, d0b, d1f, d1b;
    Distort(in, p(0), p(1), &d(0), &d(1));
    Distort(in, p(0) + h0, p(1), &d0f(0), &d0f(1));
    Distort(in, p(0) - h0, p(1), &d0b(0), &d0b(1));
    Distort(in, p(0), p(1) + h1, &d1f(0), &d1f(1));
    Distort(in, p(0), p(1) - h1, &d1b(0), &d1b(1));
    Eigen::Matrix2d J;
    J.col(0) = (d0f - d0b) / (2 * h0);
    J.col(1) = (d1f - d1b) / (2 * h1);
    J += Eigen::Matrix2d::Identity();
    const Eigen::Vector2d step = J.inverse() * (p + d - target);
    p -= step;
    if (step.squaredNorm() < kMinStepSquared) break;
  }
  *u = p(0);
  *v = p(1);
}

}  // namespace

std::string CameraModelIdToName(int model_id) {
  const ModelInfo* info = Info(model_id);
  return info ? info->name : "";
}

int CameraModelNumParams(int model_id) {
  const ModelInfo* info = Info(model_id);
  return info ? info->num_params : -1;
}

bool CameraModelIsSupported(int model_id) {
  const ModelInfo* info = Info(model_id);
  return info != nullptr && info->distortion != Distortion::kUnsupported;
}

double CameraMeanFocalLength(const Camera& camera) {
  const ModelInfo* info = Info(camera.model_id);
  if (info == nullptr || static_cast<int>(camera.params.size()) < info->num_params) return 1.0;
  return info->single_focal ? camera.params[0] : 0.5 * (camera.params[0] + camera.params[1]);
}

void CameraImageToWorld(const Camera& camera, double x, double y, double* u, double* v) {
  const ModelInfo* info = Info(camera.model_id);
  Intrinsics in = Unpack(camera);
  // Models we cannot undistort still have a pinhole part (FOV and
  // THIN_PRISM_FISHEYE start fx, fy, cx, cy): use it without distortion.
  if (in.distortion == Distortion::kUnsupported && info != nullptr &&
      static_cast<int>(camera.params.size()) >= 4) {
    in.fx = camera.params[0];
    in.fy = camera.params[1];
    in.cx = camera.params[2];
    in.cy = camera.params[3];
  }
  *u = (x - in.cx) / in.fx;
  *v = (y - in.cy) / in.fy;
  Undistort(in, u, v);
}

void CameraWorldToImage(const Camera& camera, double u, double v, double* x, double* y) {
  const Intrinsics in = Unpack(camera);
  double du = 0, dv = 0;
  Distort(in, u, v, &du, &dv);
  *x = in.fx * (u + du) + in.cx;
  *y = in.fy * (v + dv) + in.cy;
}

}  // namespace cashash
