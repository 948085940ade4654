#pragma once
// Raw arrays of the simulation checkpoints (MPM, FEM, MPM-FEM coupling): written as their bytes, read
// back with a known count; a short file is an error naming it. Every checkpoint is sealed: its bytes
// are followed by "PNETSHA2" and the SHA-256 (hex) of those bytes, so that a flipped bit or a
// truncated copy is refused before any of it is used.
#include <cstdint>
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

/// An array of any length: its element count (int64), then write_array().
template <typename T>
void write_sized_array(std::ostream& out, const std::vector<T>& a) {
    const std::int64_t size = static_cast<std::int64_t>(a.size());
    out.write(reinterpret_cast<const char*>(&size), sizeof size);
    write_array(out, a);
}

/// Reads write_sized_array()'s array of at most `most` elements; std::invalid_argument "<path>: <what> holds
/// N entries, at most M expected (corrupt checkpoint)" for a count out of range, "truncated" as read_array.
template <typename T>
void read_sized_array(std::istream& in, std::vector<T>& a, std::int64_t most, const std::string& path,
                      const std::string& what) {
    std::int64_t size = 0;
    in.read(reinterpret_cast<char*>(&size), sizeof size);
    if (!in) throw std::invalid_argument(path + ": truncated checkpoint");
    if (size < 0 || size > most)
        throw std::invalid_argument(path + ": " + what + " holds " + std::to_string(size) + " entries, at most " +
                                    std::to_string(most) + " expected (corrupt checkpoint)");
    read_array(in, a, static_cast<std::size_t>(size), path);
}

/// Writes the bytes `write` produces, then the seal, atomically (write_file_atomically).
void write_sealed_checkpoint(const std::string& path, const std::function<void(std::ostream&)>& write);

/// The checked payload of a sealed checkpoint. FileNotFoundError if path does not exist;
/// std::invalid_argument "<path>: ..." if it cannot be read, has no seal (truncated, or not a
/// checkpoint) or its bytes do not match the seal (corrupt).
std::istringstream read_sealed_checkpoint(const std::string& path);

}  // namespace pnet
