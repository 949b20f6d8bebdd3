// Writing a file so that a crash or a full disk leaves either the old complete file or the new
// complete one, never a torn one: write a temporary file beside it, flush it to disk, rename it.
#pragma once

#include <functional>
#include <memory>
#include <ostream>
#include <string>

namespace view_selection::io {

/// Calls `write(temporary_path)`, which must create and fill that file (throwing on failure),
/// then syncs it and renames it to `path`. On any failure the temporary file is removed, `path`
/// is untouched, and core::IoError says why (the writer's own exception is rethrown as is).
void writeAtomically(const std::string& path, const std::function<void(const std::string&)>& write);

/// fsync of a folder, so that the names made in it are on disk; false where that failed.
bool syncFolder(const std::string& folder);

/// Creates (or truncates) `path` and writes `size` bytes into it; throws core::IoError with the
/// system's reason ("No space left on device", ...). For writers inside writeAtomically.
void writeFileContents(const std::string& path, const void* data, size_t size);
inline void writeFileContents(const std::string& path, const std::string& text) {
  writeFileContents(path, text.data(), text.size());
}

/// writeFileContents for text produced piece by piece (a selection.json of 100k keyframes is not
/// built in memory first): `write(stream)` fills the file through a buffer; a failed write stops
/// the stream and core::IoError carries the system's reason, as writeFileContents does.
void writeFileStreaming(const std::string& path, const std::function<void(std::ostream&)>& write);

}  // namespace view_selection::io
