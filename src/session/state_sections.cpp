#include "state_sections.h"

#include "point_source_codecs.h"

#include <array>
#include <cmath>

namespace view_selection::session {

using io::readDepthMap;
using io::readIntrinsics;
using io::readParams;
using io::readPoints;
using io::readPose;
using io::writeDepthMap;
using io::writeIntrinsics;
using io::writeParams;
using io::writePoints;
using io::writePose;

namespace {

// Section tags, in the order they are written.
constexpr uint32_t kSession = io::sectionTag("SESS"), kConfig = io::sectionTag("CONF"),
                   kKeyframes = io::sectionTag("KEYF"), kMatrix = io::sectionTag("MATX"),
                   kPolicy = io::sectionTag("PLCY"), kPoints = io::sectionTag("PSRC"),
                   kStatistics = io::sectionTag("STAT"), kPairStream = io::sectionTag("PAIR"),
                   kJournalBase = io::sectionTag("JRNL"), kRevisitLinks = io::sectionTag("RVST");

void writeKeyframes(io::BinaryWriter& w, const std::vector<core::Keyframe>& keyframes) {
  w.u64(keyframes.size());
  for (const core::Keyframe& k : keyframes) writeKeyframe(w, k);
}
std::vector<core::Keyframe> readKeyframes(io::BinaryReader& r) {
  std::vector<core::Keyframe> keyframes(r.count(117, "keyframes"));
  for (core::Keyframe& k : keyframes) readKeyframe(r, k);
  return keyframes;
}

void writeRows(io::BinaryWriter& w, const std::vector<std::vector<core::TableEntry>>& rows) {
  w.u64(rows.size());
  for (const auto& row : rows) writeRow(w, row);
}
std::vector<std::vector<core::TableEntry>> readRows(io::BinaryReader& r) {
  std::vector<std::vector<core::TableEntry>> rows(r.count(8, "matrix rows"));
  for (auto& row : rows) readRow(r, row);
  return rows;
}

void writeStatistics(io::BinaryWriter& w, const SessionStatistics& s) {
  w.u64(s.frames_received);
  w.u64(s.frames_offered);
  w.u64(s.dropped.size());
  for (const auto& [reason, count] : s.dropped) {
    w.text(reason);
    w.u64(count);
  }
  w.text(s.last_error);
  w.f64(s.last_error_stamp);
  w.f64(s.last_insertion_seconds);
  w.f64(s.max_insertion_seconds);
  w.flag(s.last_frame_stamp.has_value());
  w.f64(s.last_frame_stamp.value_or(0.0));
}
SessionStatistics readStatistics(io::BinaryReader& r) {
  SessionStatistics s;
  s.frames_received = r.u64("statistics");
  s.frames_offered = r.u64("statistics");
  const size_t reasons = r.count(12, "drop reasons");
  for (size_t q = 0; q < reasons; ++q) {
    std::string reason = r.text("drop reason");
    s.dropped[reason] = r.u64("drop count");
  }
  s.last_error = r.text("last error");
  s.last_error_stamp = r.f64("statistics");
  s.last_insertion_seconds = r.f64("statistics");
  s.max_insertion_seconds = r.f64("statistics");
  const bool has_last = r.flag("statistics");
  const double last = r.f64("statistics");
  if (has_last) s.last_frame_stamp = last;
  return s;
}

}  // namespace

void writeKeyframe(io::BinaryWriter& w, const core::Keyframe& k) {
  w.f64(k.stamp);
  w.text(k.image_name);
  writeIntrinsics(w, k.intrinsics);
  writePose(w, k.pose);
  writePoints(w, k.points);
  writeDepthMap(w, k.depth);
}
void readKeyframe(io::BinaryReader& r, core::Keyframe& k) {
  k.stamp = r.finite("keyframe stamp");
  k.image_name = r.text("image name");
  k.intrinsics = readIntrinsics(r);
  k.pose = readPose(r);
  k.points = readPoints(r);
  k.depth = readDepthMap(r);
}
void writeRow(io::BinaryWriter& w, const std::vector<core::TableEntry>& row) {
  w.u64(row.size());
  for (const core::TableEntry& e : row) {
    w.i32(e.view);
    w.f64(e.value);
  }
}
void readRow(io::BinaryReader& r, std::vector<core::TableEntry>& row) {
  row.resize(r.count(12, "matrix row"));
  for (core::TableEntry& e : row) {
    e.view = r.i32("matrix entry");
    e.value = r.f64("matrix entry");
  }
}

void encodeContent(io::BinaryWriter& w, const SessionState& state) {
  size_t s = w.beginSection(kSession);
  w.text(state.producer);
  w.f64(state.saved_at);
  w.endSection(s);

  s = w.beginSection(kConfig);
  writeParams(w, core::paramsOf(state.selector.config));
  w.endSection(s);

  s = w.beginSection(kKeyframes);
  writeKeyframes(w, state.selector.keyframes);
  w.endSection(s);

  s = w.beginSection(kMatrix);
  writeRows(w, state.selector.rows);
  w.endSection(s);

  s = w.beginSection(kPolicy);
  w.i64(state.selector.policy.frames_offered);
  w.flag(state.selector.policy.last_keyframe.has_value());
  writePose(w, state.selector.policy.last_keyframe.value_or(core::CameraPose{}));
  w.flag(state.selector.last_stamp.has_value());
  w.f64(state.selector.last_stamp.value_or(0.0));
  w.endSection(s);

  s = w.beginSection(kPoints);
  w.text(state.points.name);
  writeParams(w, state.points.params);
  w.flag(state.points.map.has_value());
  if (state.points.map) writeMapState(w, *state.points.map);
  w.flag(state.points.features.has_value());
  if (state.points.features) writeFeatureState(w, *state.points.features);
  w.endSection(s);

  s = w.beginSection(kStatistics);
  writeStatistics(w, state.statistics);
  w.endSection(s);

  // Optional (readers before it skip it): the pair stream's sequence, so that it continues.
  if (state.pair_sequence) {
    s = w.beginSection(kPairStream);
    w.u64(*state.pair_sequence);
    w.endSection(s);
  }
  // Optional (readers before it skip it; a file without it has no links): the keyframes'
  // revisit_of, written after KEYF's layout was fixed.
  std::vector<std::pair<core::ViewId, core::ViewId>> links = state.revisit_links;
  for (size_t i = 0; i < state.selector.keyframes.size(); ++i)
    if (state.selector.keyframes[i].revisit_of >= 0)
      links.emplace_back(static_cast<core::ViewId>(i), state.selector.keyframes[i].revisit_of);
  if (!links.empty()) {
    s = w.beginSection(kRevisitLinks);
    w.u64(links.size());
    for (const auto& [id, earlier] : links) {
      w.i32(id);
      w.i32(earlier);
    }
    w.endSection(s);
  }
  // Optional: the id a journal's records name to follow this file.
  if (state.base_id) {
    s = w.beginSection(kJournalBase);
    w.u64(*state.base_id);
    w.endSection(s);
  }
}

SessionState decodeContent(io::BinaryReader& r, const std::string& what) {
  SessionState state;
  uint32_t seen = 0;  // bit per required section
  const std::array<uint32_t, 7> required = {kSession, kConfig, kKeyframes, kMatrix,
                                            kPolicy,  kPoints, kStatistics};
  while (!r.done()) {
    const uint32_t t = r.u32("section tag");
    const uint64_t length = r.u64("section length");
    if (length > r.left()) r.fail("truncated section");
    const std::string tag_name(reinterpret_cast<const char*>(&t), 4);
    io::BinaryReader s = r.section(static_cast<size_t>(length), tag_name);
    for (size_t q = 0; q < required.size(); ++q)
      if (required[q] == t) {
        if (seen & (1u << q)) s.fail("section repeated");
        seen |= 1u << q;
      }
    if (t == kSession) {
      state.producer = s.text("producer");
      state.saved_at = s.f64("saved at");
    } else if (t == kConfig) {
      const core::Params params = readParams(s);
      io::ParamsReader reader(params, s);
      try {
        state.selector.config.visitParameters(reader);
        state.selector.config.validate();
      } catch (const core::InvalidArgument& e) {
        s.fail(std::string("bad parameter: ") + e.what());
      }
    } else if (t == kKeyframes) {
      state.selector.keyframes = readKeyframes(s);
    } else if (t == kMatrix) {
      state.selector.rows = readRows(s);
    } else if (t == kPolicy) {
      state.selector.policy.frames_offered = s.i64("frames offered");
      if (state.selector.policy.frames_offered < 0) s.fail("negative frame count");
      const bool has_last = s.flag("policy");
      const core::CameraPose last = readPose(s);
      if (has_last) state.selector.policy.last_keyframe = last;
      const bool has_stamp = s.flag("last stamp");
      const double stamp = s.f64("last stamp");
      if (has_stamp) {
        if (!std::isfinite(stamp)) s.fail("non-finite last stamp");
        state.selector.last_stamp = stamp;
      }
    } else if (t == kPoints) {
      state.points.name = s.text("point source");
      state.points.params = readParams(s);
      if (s.flag("map")) state.points.map = readMapState(s);
      if (s.flag("features")) state.points.features = readFeatureState(s);
    } else if (t == kStatistics) {
      state.statistics = readStatistics(s);
    } else if (t == kPairStream) {
      state.pair_sequence = s.u64("pair sequence");
    } else if (t == kJournalBase) {
      state.base_id = s.u64("journal base id");
    } else if (t == kRevisitLinks) {
      state.revisit_links.resize(s.count(8, "revisit links"));
      for (auto& [id, earlier] : state.revisit_links) {
        id = s.i32("revisit link");
        earlier = s.i32("revisit link");
        if (earlier < 0 || earlier >= id) s.fail("a revisit link to a keyframe not before it");
      }
    } else {
      continue;  // a section of a later minor revision: skipped
    }
    s.expectEnd("the section");
  }
  for (size_t q = 0; q < required.size(); ++q)
    if (!(seen & (1u << q)))
      throw io::StateFileError(what + " lacks its '" +
                               std::string(reinterpret_cast<const char*>(&required[q]), 4) +
                               "' section");
  if (!state.selector.keyframes.empty()) {  // a whole state: the links go to its keyframes
    for (const auto& [id, earlier] : state.revisit_links) {
      if (static_cast<size_t>(id) >= state.selector.keyframes.size())
        throw io::StateFileError(what + " is inconsistent: a revisit link names keyframe " +
                                 std::to_string(id) + " of " +
                                 std::to_string(state.selector.keyframes.size()));
      state.selector.keyframes[static_cast<size_t>(id)].revisit_of = earlier;
    }
    state.revisit_links.clear();
  }
  if (state.selector.rows.size() != state.selector.keyframes.size())
    throw io::StateFileError(
        what + " is inconsistent: " + std::to_string(state.selector.rows.size()) +
        " matrix rows for " + std::to_string(state.selector.keyframes.size()) + " keyframes");
  return state;
}

}  // namespace view_selection::session
