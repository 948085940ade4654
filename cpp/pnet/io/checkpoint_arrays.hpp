#pragma once
// Raw arrays of the simulation checkpoints (MPM, FEM, MPM-FEM coupling): written as their bytes, read
// back with a known count; a short file is an error naming it. Every checkpoint is sealed: its bytes
// are followed by "PNETSHA2" and the SHA-256 (hex) of those bytes, so that a flipped bit or a
// truncated copy is refused before any of it is used.
#include <functional>
#include <istream>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace pnet {

template <typename T>
void write_array(std::ostream& out, const std::vector<T>& a) {
    out.write(reinterpret_cast<const char*>(a.data()), static_cast<std::streamsize>(a.size() * sizeof(T)));
}

/// Reads n elements into a; std::invalid_argument "<path>: truncated checkpoint" if the file ends first.
template <typename T>
void read_array(std::istream& in, std::vector<T>& a, std::size_t n, const std::string& path) {
    a.resize(n);
    in.read(reinterpret_cast<char*>(a.data()), static_cast<std::streamsize>(n * sizeof(T)));
    if (!in) throw std::invalid_argument(path + ": truncated checkpoint");
}

/// Writes the bytes `write` produces, then the seal, atomically (write_file_atomically).
void write_sealed_checkpoint(const std::string& path, const std::function<void(std::ostream&)>& write);

/// The checked payload of a sealed checkpoint. FileNotFoundError if path does not exist;
/// std::invalid_argument "<path>: ..." if it cannot be read, has no seal (truncated, or not a
/// checkpoint) or its bytes do not match the seal (corrupt).
std::istringstream read_sealed_checkpoint(const std::string& path);

}  // namespace pnet
