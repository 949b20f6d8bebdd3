// camera.yaml: the flat format and ROS calibration files, whatever the bytes.
#include "fuzz_target.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/tum_dataset.h"

using namespace view_selection;

VIEW_SELECTION_FUZZ_TARGET(camera_yaml) {
  const std::string path = fuzz::writeScratch("camera.yaml", data, size);
  try {
    const core::PinholeIntrinsics k = io::loadCameraYaml(path);
    if (!k.isValid()) fuzz::broken("loadCameraYaml returned invalid intrinsics");
  } catch (const core::Error&) {
  }
}
