// The inverse of CameraImageToWorld: normalised (u, v) -> distorted pixel.
// Used to test undistortion and to synthesise observations.
#pragma once

#include "cashash/base/types.h"

namespace cashash {

void CameraWorldToImage(const Camera& camera, double u, double v, double* x, double* y);

}  // namespace cashash
