// Where a frame's camera is relative to an earlier keyframe's, measured from their images: the
// revisit rule's answer to drift (docs/design.md, "Revisits"). The core asks through this
// interface only; registration/ implements it with OpenCV (ORB and PnP).
#pragma once

#include "view_selection/core/frame.h"
#include "view_selection/core/types.h"

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

namespace view_selection::core {

class FrameRegistration {
 public:
  virtual ~FrameRegistration() = default;
  /// Keyframe `id` was made from `frame` (pose, image, depth): keep what registering a later
  /// frame to it needs. A frame without an image or depth leaves nothing: no frame registers to
  /// that keyframe.
  virtual void keyframeAdded(ViewId id, const Frame& frame) = 0;
  /// `frame`'s camera in keyframe `id`'s camera frame (camera-to-keyframe-camera, in the
  /// keyframe's depth units), measured from the frame's image and the keyframe's image and
  /// depth; none when they do not register. Frames are asked about in stamp order; one frame may
  /// be asked about several keyframes.
  virtual std::optional<CameraPose> relativePose(const Frame& frame, ViewId id) = 0;
  /// Up to `max` keyframes with an id below `below` whose images look most like `frame`'s, most
  /// alike first (appearance alone: drift does not move it). Empty when it keeps no images.
  virtual std::vector<ViewId> alikeKeyframes(const Frame& frame, ViewId below, size_t max) = 0;
  /// Forgets every keyframe (the selector's reset, or a session restored without images).
  virtual void clear() = 0;
  /// What it keeps of keyframe `id`, as bytes that restoreKept() of a later instance takes: a
  /// session continued after a restart registers to the keyframes made before it
  /// (session/registration_log.h). Empty when nothing is kept of it.
  virtual std::vector<uint8_t> keptBytes(ViewId id) const = 0;
  /// Keeps keyframe `id` as keptBytes() gave it. False, and nothing kept of it, when the bytes
  /// are not such.
  virtual bool restoreKept(ViewId id, const std::vector<uint8_t>& bytes) = 0;
};

}  // namespace view_selection::core
