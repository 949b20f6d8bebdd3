// The sections of a saved session (docs/state_file.md, "Format"): the content of a state file
// after its header, and the trailer of a journal record; and the keyframes and matrix rows both
// hold. Shared by session/state_file.cpp and session/journal.cpp.
#pragma once

#include "view_selection/io/binary_codec.h"
#include "view_selection/session/session_state.h"

#include <string>
#include <vector>

namespace view_selection::session {

void writeKeyframe(io::BinaryWriter& w, const core::Keyframe& k);
void readKeyframe(io::BinaryReader& r, core::Keyframe& k);
void writeRow(io::BinaryWriter& w, const std::vector<core::TableEntry>& row);
void readRow(io::BinaryReader& r, std::vector<core::TableEntry>& row);

/// The sections of `state` (SESS, CONF, KEYF, MATX, PLCY, PSRC, STAT; PAIR and JRNL when set).
void encodeContent(io::BinaryWriter& w, const SessionState& state);
/// Reads sections up to the end of `r`; `what` names the state in errors (io::StateFileError).
SessionState decodeContent(io::BinaryReader& r, const std::string& what);

}  // namespace view_selection::session
