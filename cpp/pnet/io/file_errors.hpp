#pragma once
// Errors of reading files, shared by every reader (checkpoints, model files, scenes): a missing file is
// its own type, so that callers (and Python, as FileNotFoundError) tell it from a malformed one.
#include <stdexcept>

namespace pnet {

/// A file that does not exist (FileNotFoundError in Python).
class FileNotFoundError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace pnet
