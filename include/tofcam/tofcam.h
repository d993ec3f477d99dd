#pragma once
/// \file
/// Umbrella header of the core library (tofcam::tofcam).

#include "tofcam/core/atomic_file.h"
#include "tofcam/core/camera.h"
#include "tofcam/core/camera_intrinsics.h"
#include "tofcam/core/error.h"
#include "tofcam/core/frame.h"
#include "tofcam/core/image.h"
#include "tofcam/core/pan_unit.h"
#include "tofcam/core/pixel_flags.h"
#include "tofcam/core/units.h"
#include "tofcam/version.h"
