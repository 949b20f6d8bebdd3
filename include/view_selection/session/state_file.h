// The state file: one online session saved so that a restarted node, or select_views --state,
// continues it exactly. The byte layout is in docs/state_file.md; the binary types are
// io/binary_codec.h, the checksums io/crc32.h, and a file is written atomically
// (io/atomic_file.h). A file whose content cannot be used throws io::StateFileError.
#pragma once

#include "view_selection/io/binary_codec.h"
#include "view_selection/session/session_state.h"

#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::session {

/// The current format version; readers accept this one and older ones.
inline constexpr uint32_t kStateFormatVersion = 1;

std::vector<uint8_t> encodeState(const SessionState& state);
/// Throws io::StateFileError naming what is wrong (and `name`, when given, in the message).
SessionState decodeState(const uint8_t* data, size_t size, const std::string& name = "");
/// Writes atomically (a crash leaves the old complete file or the new one); returns the size in
/// bytes. Throws core::IoError (nothing is left behind then).
size_t writeStateFile(const std::string& path, const SessionState& state);
/// Throws core::IoError when the file cannot be read, io::StateFileError when its content is
/// bad.
SessionState readStateFile(const std::string& path);

}  // namespace view_selection::session
