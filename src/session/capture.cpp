#include "view_selection/session/capture.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/binary_codec.h"
#include "view_selection/points/point_source_factory.h"

#include <functional>
#include <string>
#include <type_traits>
#include <variant>

namespace view_selection::session {

namespace {

std::string describeSource(const std::string& name, const core::Params& params) {
  std::string text = "'" + name + "' (";
  std::function<void(const core::Params&)> add = [&](const core::Params& ps) {
    for (const core::Param& p : ps) {
      if (p.group) {
        add(p.children);
        continue;
      }
      text += p.name + "=";
      std::visit(
          [&](const auto& v) {
            using T = std::decay_t<decltype(v)>;
            if constexpr (std::is_same_v<T, std::string>)
              text += v;
            else if constexpr (std::is_same_v<T, bool>)
              text += v ? "true" : "false";
            else if constexpr (std::is_same_v<T, double>)
              text += core::formatNumber(v);
            else
              text += std::to_string(v);
          },
          p.value);
      text += " ";
    }
  };
  add(params);
  if (text.back() == ' ') text.pop_back();
  return text + ")";
}

}  // namespace

PointSourceState capturePointSource(const core::PointSource& source) {
  PointSourceState s;
  s.name = source.name();
  s.params = source.params();
  if (auto* map = points::mapSourceOf(source)) s.map = map->state();
  if (auto* features = points::featureSourceOf(source)) s.features = features->state();
  return s;
}

SessionState captureSession(const core::ViewSelector& selector) {
  SessionState s;
  s.selector = selector.state();
  s.points = capturePointSource(selector.pointSource());
  return s;
}

void restoreSession(core::ViewSelector& selector, const SessionState& state) {
  core::PointSource& source = selector.pointSource();
  if (state.points.name != source.name() || state.points.params != source.params())
    throw core::InvalidArgument(
        "the saved session was made with point source " +
        describeSource(state.points.name, state.points.params) + ", this one uses " +
        describeSource(source.name(), source.params()) + ": its points cannot continue here");
  try {
    selector.restore(state.selector);
    source.reset();
    if (auto* map = points::mapSourceOf(source)) {
      if (!state.points.map) throw core::InvalidInput("the saved session has no map");
      map->restore(*state.points.map);
    }
    if (auto* features = points::featureSourceOf(source)) {
      if (!state.points.features) throw core::InvalidInput("the saved session has no features");
      features->restore(*state.points.features);
    }
  } catch (...) {
    selector.reset();
    throw;
  }
}

std::unique_ptr<core::ViewSelector> selectorFor(const SessionState& state) {
  // The point source's parameters from the saved ones, by name (groups flattened: "auto").
  core::Params flat;
  std::function<void(const core::Params&)> add = [&](const core::Params& ps) {
    for (const core::Param& p : ps) {
      if (p.group)
        add(p.children);
      else
        flat.push_back(p);
    }
  };
  add(state.points.params);
  points::PointSourceParams params;
  io::BinaryReader unused(nullptr, 0, "saved point source parameters");
  io::ParamsReader reader(flat, unused);
  params.visitParameters(reader);
  params.validate();
  auto selector = std::make_unique<core::ViewSelector>(
      state.selector.config,
      points::makePointSource(state.points.name, params, state.selector.config.matrix.occlusion));
  restoreSession(*selector, state);
  return selector;
}

}  // namespace view_selection::session
