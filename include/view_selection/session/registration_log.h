// What the revisit rule's registration keeps of each keyframe (its image features with their
// points from the keyframe's depth), in a file beside ~state_file (the path + kSuffix), so that a
// session continued after a restart recognises revisits of the keyframes made before it: the
// state file holds no images, and without this file a continued node registered later frames to
// the keyframes made after its restart only (docs/state_file.md, "The registration log").
//
// A cache of the state file, not part of it: each record carries its keyframe's id and stamp and
// a CRC, and only the records whose id and stamp are a keyframe of the continued session are
// used. A missing, torn or foreign record means that keyframe is not registered to, nothing else;
// so the records are appended without a flush to disk.
#pragma once

#include "view_selection/core/error_resistance_matrix.h"
#include "view_selection/core/frame_registration.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::session {

struct RegistrationRecord {
  int32_t id = -1;             ///< the keyframe's id
  double stamp = 0.0;          ///< and stamp [s]: a record names its keyframe by both
  std::vector<uint8_t> bytes;  ///< what the registration kept (OrbRegistration::keptBytes)
};

constexpr const char* kRegistrationLogSuffix = ".registration";
/// The registration log of the state file at `state_path`.
std::string registrationLogPath(const std::string& state_path);

/// One record: u32 tag "VSRG", u32 payload length, the payload (i32 id, f64 stamp, the bytes),
/// u32 CRC-32 of the payload; little-endian.
std::vector<uint8_t> encodeRegistrationRecord(const RegistrationRecord& record);
/// The records of `size` bytes in order, up to the first that is torn or corrupt; `unread`
/// (optional) gets the bytes from there on.
std::vector<RegistrationRecord> decodeRegistrationRecords(const uint8_t* data, size_t size,
                                                          size_t* unread = nullptr);
/// The file's records (decodeRegistrationRecords); none when the file is missing. Throws
/// core::IoError when it exists but cannot be read.
std::vector<RegistrationRecord> readRegistrationLog(const std::string& path,
                                                    size_t* unread = nullptr);
/// Appends one record (the file made when missing), without a flush to disk. Throws
/// core::IoError.
void appendRegistrationRecord(const std::string& path, const RegistrationRecord& record);
/// Replaces the file with these records, atomically (an empty list: an empty file). Throws
/// core::IoError.
void writeRegistrationLog(const std::string& path, const std::vector<RegistrationRecord>& records);

/// A session's registration log: kept as the keyframes come, emptied when a session starts,
/// read back when one is continued. Errors are returned (a message), never thrown: a log that
/// cannot be written costs the recognition of revisits after a restart, nothing else.
class RegistrationLog {
 public:
  /// `state_path` empty (no state file): nothing is kept on disk.
  RegistrationLog(const std::string& state_path, core::FrameRegistration& registration);

  const std::string& path() const { return path_; }
  /// A new session (none continued, a reset, a time jump): the file emptied (its folder made
  /// when missing). Returns an error message, or empty.
  std::string startSession();

  struct Continued {
    size_t restored = 0;  ///< keyframes whose features are back
    size_t dropped = 0;   ///< records of no continued keyframe (or refused), dropped from the file
    size_t unread = 0;    ///< bytes at the end that are no record (torn), dropped
    std::string error;    ///< why the file could not be read or rewritten, or empty
  };
  /// A continued session, after the selector's restore (which cleared the registration): the
  /// newest record of each of `keyframes` (same id and stamp) restored into the registration;
  /// the file rewritten without the others.
  Continued continueSession(const core::ErrorResistanceMatrix& keyframes);
  /// Keyframe `id`, made at `stamp`, was inserted: what the registration kept of it appended
  /// (nothing when it kept nothing). Returns an error message, or empty; after an error nothing
  /// more is appended this session (a torn record ends what a restart reads).
  std::string keyframeAdded(core::ViewId id, double stamp);

 private:
  std::string path_;
  core::FrameRegistration& registration_;
  bool failed_ = false;
};

}  // namespace view_selection::session
