#pragma once
// Whole-file writes that never leave a half-written file behind: simulation
// output (frames, checkpoints, plots) is written to a temporary file in the same
// folder and renamed over the destination only once it is complete, so a crash,
// a full disk or an exception mid-write leaves any previous file untouched and a
// reader never sees a truncated frame.
//
// rename() within one file system is atomic on POSIX. No fsync is done: this
// guards against failures of the process, not against power loss (frames are
// written often and cheaply re-created).
#include <functional>
#include <ostream>
#include <string>

namespace pnet {

/// Calls write() on a binary stream to "<path>.tmp.<pid>", flushes and checks the stream,
/// then renames the temporary file over path. On any failure (the temporary file cannot be
/// created, write() throws, the stream goes bad, the rename fails) the temporary file is
/// removed, an existing file at path is left as it was, and std::runtime_error
/// "<path>: <what failed>" is thrown.
void write_file_atomically(const std::string& path, const std::function<void(std::ostream&)>& write);

/// write_file_atomically() of a string's bytes.
void write_text_atomically(const std::string& path, const std::string& text);

}  // namespace pnet
