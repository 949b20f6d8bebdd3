// Typed errors thrown by the core. The ROS layer and the tools catch them at the boundary and
// turn them into a service answer, a throttled log line or a one-line message and exit code.
#pragma once

#include <stdexcept>
#include <string>

namespace view_selection::core {

/// Base of every error the core throws on purpose.
class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

/// A parameter or argument is out of its documented range.
class InvalidArgument : public Error {
 public:
  using Error::Error;
};

/// A file could not be read or written, or is malformed (the message names file and line).
class IoError : public Error {
 public:
  using Error::Error;
};

/// An input (image, depth, pose, intrinsics) is unusable.
class InvalidInput : public Error {
 public:
  using Error::Error;
};

}  // namespace view_selection::core
