#pragma once
// Raw arrays of the simulation checkpoints (MPM, FEM, MPM-FEM coupling): written as their bytes, read
// back with a known count; a short file is an error naming it.
#include <istream>
#include <ostream>
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

}  // namespace pnet
