// Camera paths and bookmarks: one JSON format read by render, bench and eval (and written by
// the viewer later):
//   {"cameras": [{"eye": [x, y, z], "target": [x, y, z], "up": [0, 1, 0], "fov": 40}, ...]}
// in the input's world coordinates. A bare array of camera objects is accepted too; "up"
// defaults to 0,1,0 and "fov" to 40.
#pragma once
#include <string>
#include <vector>

#include "viewer/camera.h"

namespace sa {

Result<std::vector<Camera>> readCameraPath(const std::string& path, int width, int height);
Status writeCameraPath(const std::string& path, const std::vector<Camera>& cams);

}  // namespace sa
