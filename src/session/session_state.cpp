#include "view_selection/session/session_state.h"

namespace view_selection::session {

bool SessionStatistics::operator==(const SessionStatistics& o) const {
  return frames_received == o.frames_received && frames_offered == o.frames_offered &&
         dropped == o.dropped && last_error == o.last_error &&
         last_error_stamp == o.last_error_stamp &&
         last_insertion_seconds == o.last_insertion_seconds &&
         max_insertion_seconds == o.max_insertion_seconds && last_frame_stamp == o.last_frame_stamp;
}

}  // namespace view_selection::session
