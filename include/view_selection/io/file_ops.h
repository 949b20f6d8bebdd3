// POSIX file operations beside io/atomic_file.h, for the state file and its journal: a whole
// file read, an append flushed to disk, a truncation, and a bad file moved aside. Each throws
// core::IoError with the system's reason.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace view_selection::io {

/// The file's bytes. Throws core::IoError when it cannot be opened or read.
std::vector<uint8_t> readFileBytes(const std::string& path);
/// Appends `bytes` to the file (made when missing) and flushes it to disk (fdatasync; not with
/// `flush` false, for a cache whose lost tail costs nothing). Throws core::IoError; the file may
/// then end in a torn record, which readers drop.
void appendToFile(const std::string& path, const std::vector<uint8_t>& bytes, bool flush = true);
/// Cuts the file to `size` bytes (made empty when missing) and flushes it. Throws core::IoError.
void truncateFile(const std::string& path, size_t size);
/// Renames a bad file aside, to "<path>.bad-<UTC YYYYmmddTHHMMSS>[-n]", never over an existing
/// file. Returns the new path; throws core::IoError when the rename fails.
std::string moveAside(const std::string& path);

}  // namespace view_selection::io
