#include "view_selection/session/registration_log.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/atomic_file.h"
#include "view_selection/io/binary_codec.h"
#include "view_selection/io/crc32.h"
#include "view_selection/io/file_ops.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <system_error>
#include <utility>

namespace view_selection::session {

namespace {

constexpr uint32_t kRecordTag = io::sectionTag("VSRG");
constexpr size_t kHeaderBytes = 8;              // tag, payload length
constexpr size_t kPayloadMinBytes = 4 + 8;      // id, stamp
constexpr size_t kMaxPayloadBytes = 64u << 20;  // far above a keyframe's (about 25 KB)

}  // namespace

std::string registrationLogPath(const std::string& state_path) {
  return state_path + kRegistrationLogSuffix;
}

std::vector<uint8_t> encodeRegistrationRecord(const RegistrationRecord& record) {
  io::BinaryWriter w;
  w.bytes.reserve(kHeaderBytes + kPayloadMinBytes + record.bytes.size() + 4);
  w.u32(kRecordTag);
  w.u32(static_cast<uint32_t>(kPayloadMinBytes + record.bytes.size()));
  w.i32(record.id);
  w.f64(record.stamp);
  w.raw(record.bytes.data(), record.bytes.size());
  w.u32(io::crc32(w.bytes.data() + kHeaderBytes, w.bytes.size() - kHeaderBytes));
  return std::move(w.bytes);
}

std::vector<RegistrationRecord> decodeRegistrationRecords(const uint8_t* data, size_t size,
                                                          size_t* unread) {
  std::vector<RegistrationRecord> out;
  size_t at = 0;
  while (size - at >= kHeaderBytes) {
    io::BinaryReader header(data + at, kHeaderBytes, "registration record");
    const uint32_t tag = header.u32("tag"), length = header.u32("length");
    if (tag != kRecordTag || length < kPayloadMinBytes || length > kMaxPayloadBytes ||
        size - at - kHeaderBytes < static_cast<size_t>(length) + 4)
      break;
    const uint8_t* payload = data + at + kHeaderBytes;
    io::BinaryReader r(payload, static_cast<size_t>(length) + 4, "registration record");
    RegistrationRecord record;
    record.id = r.i32("id");
    record.stamp = r.f64("stamp");
    const uint8_t* bytes = r.take(length - kPayloadMinBytes, "bytes");
    if (r.u32("checksum") != io::crc32(payload, length) || record.id < 0 ||
        !std::isfinite(record.stamp))
      break;
    record.bytes.assign(bytes, bytes + (length - kPayloadMinBytes));
    out.push_back(std::move(record));
    at += kHeaderBytes + length + 4;
  }
  if (unread) *unread = size - at;
  return out;
}

std::vector<RegistrationRecord> readRegistrationLog(const std::string& path, size_t* unread) {
  std::error_code error;
  if (!std::filesystem::exists(path, error)) {
    if (unread) *unread = 0;
    return {};
  }
  const std::vector<uint8_t> bytes = io::readFileBytes(path);
  return decodeRegistrationRecords(bytes.data(), bytes.size(), unread);
}

void appendRegistrationRecord(const std::string& path, const RegistrationRecord& record) {
  io::appendToFile(path, encodeRegistrationRecord(record), /*flush=*/false);
}

void writeRegistrationLog(const std::string& path, const std::vector<RegistrationRecord>& records) {
  std::vector<uint8_t> bytes;
  for (const RegistrationRecord& r : records) {
    const std::vector<uint8_t> one = encodeRegistrationRecord(r);
    bytes.insert(bytes.end(), one.begin(), one.end());
  }
  io::writeAtomically(path, [&](const std::string& temporary) {
    io::writeFileContents(temporary, bytes.data(), bytes.size());
  });
}

RegistrationLog::RegistrationLog(const std::string& state_path,
                                 core::FrameRegistration& registration)
    : path_(state_path.empty() ? std::string() : registrationLogPath(state_path)),
      registration_(registration) {}

std::string RegistrationLog::startSession() {
  failed_ = false;
  if (path_.empty()) return {};
  // The state file's folder, made here as the state keeper makes it (it writes later).
  std::error_code ignored;  // a folder that cannot be made fails the write below
  const std::filesystem::path folder = std::filesystem::path(path_).parent_path();
  if (!folder.empty()) std::filesystem::create_directories(folder, ignored);
  try {
    writeRegistrationLog(path_, {});
  } catch (const core::IoError& e) {
    failed_ = true;
    return std::string("cannot empty the registration log: ") + e.what();
  }
  return {};
}

RegistrationLog::Continued RegistrationLog::continueSession(
    const core::ErrorResistanceMatrix& keyframes) {
  failed_ = false;
  Continued out;
  if (path_.empty()) return out;
  std::vector<RegistrationRecord> records;
  try {
    records = readRegistrationLog(path_, &out.unread);
  } catch (const core::IoError& e) {
    out.error = std::string("cannot read the registration log: ") + e.what();
  }
  // A record of a keyframe that the state file did not keep (a crash before its save) names an
  // id that a later keyframe may take: only the same id and stamp count, the newest record first.
  std::map<core::ViewId, RegistrationRecord> newest;
  for (RegistrationRecord& r : records)
    if (static_cast<size_t>(r.id) < keyframes.size() && keyframes.keyframe(r.id).stamp == r.stamp)
      newest[r.id] = std::move(r);
  std::vector<RegistrationRecord> used;
  for (auto& [id, record] : newest)
    if (registration_.restoreKept(id, record.bytes)) used.push_back(std::move(record));
  out.restored = used.size();
  out.dropped = records.size() - used.size();
  if (out.dropped > 0 || out.unread > 0 || !out.error.empty()) {
    try {
      writeRegistrationLog(path_, used);
    } catch (const core::IoError& e) {
      failed_ = true;
      out.error += (out.error.empty() ? "" : "; ") +
                   std::string("cannot rewrite the registration log: ") + e.what();
    }
  }
  return out;
}

std::string RegistrationLog::keyframeAdded(core::ViewId id, double stamp) {
  if (path_.empty() || failed_) return {};
  RegistrationRecord record;
  record.bytes = registration_.keptBytes(id);
  if (record.bytes.empty()) return {};  // no depth, too few features, or the rule is off
  record.id = id;
  record.stamp = stamp;
  try {
    appendRegistrationRecord(path_, record);
  } catch (const core::IoError& e) {
    failed_ = true;
    return std::string("cannot append to the registration log: ") + e.what();
  }
  return {};
}

}  // namespace view_selection::session
