// The offline tests name every layer's types unqualified (TumDataset, ViewSelector, ...): the
// layers' namespaces are opened into view_selection here. Tests only; the ROS tests, which see
// the generated messages of the same names, qualify instead.
#pragma once

namespace view_selection {
namespace core {}
namespace images {}
namespace points {}
namespace io {}
namespace session {}
namespace sim {}
namespace eval {}
using namespace core;
using namespace images;
using namespace points;
using namespace io;
using namespace session;
using namespace sim;
using namespace eval;
}  // namespace view_selection
