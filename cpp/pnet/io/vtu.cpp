#include "pnet/io/vtu.hpp"

#include <cstdio>
#include <stdexcept>

#include "pnet/io/atomic_file.hpp"

namespace pnet {

namespace {

void append_double(std::string& out, double v) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.17g ", v);
    out += buffer;
}

bool plain_name(const std::string& name) {
    if (name.empty()) return false;
    for (char c : name)
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-'))
            return false;
    return true;
}

/// One <DataArray> of `count` tuples; vectors of dim components are padded to 3.
void append_field(std::string& out, const std::string& path, const VtuField& f, std::size_t count, int dim) {
    if (!plain_name(f.name)) throw std::invalid_argument(path + ": field name '" + f.name + "' is not plain");
    if (f.components != 1 && f.components != dim)
        throw std::invalid_argument(path + ": field " + f.name + " has " + std::to_string(f.components) +
                                    " components (1 or " + std::to_string(dim) + ")");
    if (f.values.size() != count * f.components)
        throw std::invalid_argument(path + ": field " + f.name + " has " + std::to_string(f.values.size()) +
                                    " values, expected " + std::to_string(count * f.components));
    const int written = f.components == 1 ? 1 : 3;
    out += "<DataArray type=\"Float64\" Name=\"" + f.name + "\" NumberOfComponents=\"" + std::to_string(written) +
           "\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < count; ++i) {
        for (int k = 0; k < written; ++k) append_double(out, k < f.components ? f.values[i * f.components + k] : 0.0);
        out += "\n";
    }
    out += "</DataArray>\n";
}

}  // namespace

void write_vtu(const std::string& path, const VtuMesh& m) {
    if (m.dim != 2 && m.dim != 3) throw std::invalid_argument(path + ": dim must be 2 or 3, got " + std::to_string(m.dim));
    const std::size_t d = static_cast<std::size_t>(m.dim);
    if (m.position.size() % d != 0)
        throw std::invalid_argument(path + ": " + std::to_string(m.position.size()) + " coordinates is not " +
                                    std::to_string(d) + " per point");
    const std::size_t n = m.position.size() / d, per = m.cells.empty() ? 1 : d + 1;
    if (m.cells.size() % per != 0)
        throw std::invalid_argument(path + ": " + std::to_string(m.cells.size()) + " cell indices is not " +
                                    std::to_string(per) + " per cell");
    const std::size_t cells = m.cells.empty() ? n : m.cells.size() / per;
    for (int i : m.cells)
        if (i < 0 || static_cast<std::size_t>(i) >= n)
            throw std::invalid_argument(path + ": cell node " + std::to_string(i) + " out of range (" +
                                        std::to_string(n) + " points)");
    std::string out =
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" "
        "header_type=\"UInt64\">\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"" +
        std::to_string(n) + "\" NumberOfCells=\"" + std::to_string(cells) + "\">\n<PointData>\n";
    for (const VtuField& f : m.point_data) append_field(out, path, f, n, m.dim);
    out += "</PointData>\n<CellData>\n";
    for (const VtuField& f : m.cell_data) append_field(out, path, f, cells, m.dim);
    out += "</CellData>\n<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
    for (std::size_t i = 0; i < n; ++i) {
        for (std::size_t k = 0; k < 3; ++k) append_double(out, k < d ? m.position[d * i + k] : 0.0);
        out += "\n";
    }
    out += "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
    for (std::size_t c = 0; c < cells; ++c) {
        for (std::size_t k = 0; k < per; ++k)
            out += std::to_string(m.cells.empty() ? static_cast<int>(c) : m.cells[c * per + k]) + " ";
        out += "\n";
    }
    out += "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
    for (std::size_t c = 0; c < cells; ++c) out += std::to_string((c + 1) * per) + (c % 16 == 15 ? "\n" : " ");
    const char* type = per == 1 ? "1" : per == 3 ? "5" : "10";  // VTK_VERTEX, VTK_TRIANGLE, VTK_TETRA
    out += "\n</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
    for (std::size_t c = 0; c < cells; ++c) out += std::string(type) + (c % 32 == 31 ? "\n" : " ");
    out += "\n</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
    write_file_atomically(path, [&](std::ostream& stream) { stream.write(out.data(), std::streamsize(out.size())); });
}

}  // namespace pnet
