// A selector's session copied out, and a session continued in a selector: keyframes, E, the
// policy, and the point source's own state (its tracks or map, reached through the point-source
// factory, the one place that knows the concrete sources).
#pragma once

#include "view_selection/core/view_selector.h"
#include "view_selection/session/session_state.h"

#include <memory>

namespace view_selection::session {

/// The point source's part of a selector's session: its name, parameters and own state.
PointSourceState capturePointSource(const core::PointSource& source);
/// The selector's and its point source's state, copied (call it under the lock that guards the
/// selector; it copies points and shares depth maps and descriptors, which are never written).
SessionState captureSession(const core::ViewSelector& selector);
/// Continues `selector` from `state` (keyframes, E and the policy as saved, the point source's
/// tracks or map). Throws core::InvalidArgument when `state` was made with another point source
/// or other point-source parameters (nothing changes then), core::InvalidInput when it is
/// inconsistent (`selector` is reset then: empty). The selector's config becomes the saved one;
/// apply another with ViewSelector::setConfig afterwards.
void restoreSession(core::ViewSelector& selector, const SessionState& state);
/// A selector (with the saved point source and its parameters, the saved method parameters)
/// that continues `state`: what select_views --state re-selects from. Throws
/// core::InvalidArgument / core::InvalidInput for a state that cannot be continued.
std::unique_ptr<core::ViewSelector> selectorFor(const SessionState& state);

}  // namespace view_selection::session
