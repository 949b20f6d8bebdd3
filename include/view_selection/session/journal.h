// The state journal, `<state file>.journal` (docs/state_file.md, "The journal"): records of
// what changed in a session since the last save (SessionDelta), each with a length and CRC-32s
// so that a torn tail is found, replayed over the base file they name.
#pragma once

#include "view_selection/session/session_state.h"

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::session {

/// Applies `delta` to `state`; afterwards `state` equals the session the delta was captured
/// from. Throws io::StateFileError when it does not fit (a new keyframe or row missing, an id
/// out of range); `state` is unchanged then.
void applyDelta(SessionState& state, const SessionDelta& delta);
/// `earlier` followed by `later`, as one delta.
void mergeDelta(SessionDelta& earlier, SessionDelta later);

/// One record of a journal: follows the base with id `base_id`, `index` counting from 0 after
/// it. Layout in docs/state_file.md (a length and CRC-32s, so a torn tail is found).
std::vector<uint8_t> encodeJournalRecord(uint64_t base_id, uint64_t index,
                                         const SessionDelta& delta);

/// A journal read against its base.
struct JournalReplay {
  uint64_t records = 0;   ///< applied
  uint64_t stale = 0;     ///< of another base (an older one, before a compaction): ignored
  size_t good_bytes = 0;  ///< the prefix that holds complete records (append after it)
  size_t total_bytes = 0;
  std::string error;  ///< why the tail from good_bytes on was dropped; empty: none
};
/// Applies the records of `data` that follow `state.base_id` to `state`, in order, up to the
/// first torn or corrupt record (reported in `error`, never thrown).
JournalReplay replayJournal(SessionState& state, const uint8_t* data, size_t size,
                            const std::string& name = "");
/// `path` + ".journal".
std::string journalPath(const std::string& path);
/// The state file with its journal applied (readStateFile, then replayJournal when the journal
/// exists). `replay` (optional) says what the journal gave.
SessionState readSession(const std::string& path, JournalReplay* replay = nullptr);

}  // namespace view_selection::session
