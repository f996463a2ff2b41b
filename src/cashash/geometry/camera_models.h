// The subset of COLMAP's camera models needed to normalise image points for
// essential-matrix estimation: pixel -> normalised camera coordinates,
// undistorting where the model has distortion.
#pragma once

#include <string>
#include <vector>

#include "cashash/base/types.h"

namespace cashash {

// COLMAP's model name for a model id ("SIMPLE_RADIAL"), or "" if unknown.
std::string CameraModelIdToName(int model_id);
// Number of parameters of a model, or -1 if unknown.
int CameraModelNumParams(int model_id);
// True when the model id is one we can normalise points for.
bool CameraModelIsSupported(int model_id);
// Mean focal length of a camera (pixels).
double CameraMeanFocalLength(const Camera& camera);
// Pixel (x, y) -> normalised, undistorted (u, v) with z = 1.
void CameraImageToWorld(const Camera& camera, double x, double y, double* u, double* v);

}  // namespace cashash
