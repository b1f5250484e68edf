// Pinhole camera in the world frame. Like Blender's and glTF's cameras it looks down its local -Z with +Y
// up; `forward` is that -Z axis in world space. Pixel (0, 0) is the top-left corner of the image.
#pragma once
#include "sim_core/intersect.h"
#include "sim_core/math.h"

namespace sim_core {

struct Camera {
  Vec3 position;
  Vec3 right{1.f, 0.f, 0.f};    // unit, world +X of the camera
  Vec3 up{0.f, 0.f, 1.f};       // unit, world +Y of the camera
  Vec3 forward{0.f, 1.f, 0.f};  // unit, world -Z of the camera (viewing direction)
  float vfov = 0.6911f;         // vertical field of view, radians
  int width = 64, height = 64;
  // A window of a larger frame: this camera's pixels are pixels [crop_x, crop_x + width) x
  // [crop_y, crop_y + height) of a full_width x full_height image (0 = width / height: no window). Rays,
  // projection and sampling seeds are the full frame's, so a frame traced window by window (tiles of a
  // preview, bands of a progressive render) equals the frame traced at once.
  int crop_x = 0, crop_y = 0, full_width = 0, full_height = 0;

  void validate() const;  // throws std::invalid_argument
  float tan_half() const;
  int frame_width() const { return full_width > 0 ? full_width : width; }
  int frame_height() const { return full_height > 0 ? full_height : height; }
  // Ray through continuous pixel coordinates (x right, y down; pixel centres at +0.5). Unit direction.
  Ray primary(float px, float py) const;
  // The same through continuous coordinates of the whole frame (primary(px, py) is
  // primary_frame(px + crop_x, py + crop_y)): a window that computes its samples' positions in the frame
  // traces the frame's rays to the bit.
  Ray primary_frame(float fx, float fy) const;
  // Projects a world point: continuous pixel coordinates and camera-space depth along forward.
  // Returns false when the point is behind the camera.
  bool project(Vec3 p, float* px, float* py, float* depth) const;
  // Projects a direction (a point at infinity).
  bool project_direction(Vec3 d, float* px, float* py) const;
  // Same camera with a different image size (resolution scaling keeps the field of view).
  Camera resized(int w, int h) const;
  // Same camera moved along its right axis (stereo eyes).
  Camera shifted(float dx) const;
};

}  // namespace sim_core
