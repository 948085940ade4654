#include "pnet/io/ply.hpp"

#include <array>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "pnet/io/atomic_file.hpp"

namespace pnet {

namespace {

constexpr std::array<const char*, 8> kProperties = {"x", "y", "z", "vx", "vy", "vz", "mass", "hardening"};
constexpr std::size_t kVertexBytes = kProperties.size() * sizeof(double);

// A header longer than this is not one of ours; the limit stops a large non-PLY file from
// being scanned line by line.
constexpr std::size_t kMaxHeaderBytes = 64 * 1024;

static_assert(sizeof(double) == 8 && std::numeric_limits<double>::is_iec559, "PLY doubles are IEEE-754 binary64");

// Byte by byte, so that the file is little-endian whatever the host's byte order.
void put_le_double(char* dst, double value) {
    std::uint64_t bits;
    std::memcpy(&bits, &value, 8);
    for (int i = 0; i < 8; ++i) dst[i] = static_cast<char>((bits >> (8 * i)) & 0xff);
}

double get_le_double(const char* src) {
    std::uint64_t bits = 0;
    for (int i = 0; i < 8; ++i) bits |= std::uint64_t(static_cast<unsigned char>(src[i])) << (8 * i);
    double value;
    std::memcpy(&value, &bits, 8);
    return value;
}

void check_size(const std::string& path, const char* field, std::size_t actual, std::size_t expected,
                const std::string& why) {
    if (actual != expected) {
        throw std::invalid_argument(path + ": " + field + " has " + std::to_string(actual) + " values, expected " +
                                    std::to_string(expected) + " (" + why + ")");
    }
}

// Strict unsigned decimal: "12" but not "-1", "1e3", "12abc" or "" (istream >> would accept some).
bool parse_count(const std::string& text, std::uint64_t& value) {
    if (text.empty() || text.size() > 19) return false;
    value = 0;
    for (char c : text) {
        if (c < '0' || c > '9') return false;
        value = value * 10 + std::uint64_t(c - '0');
    }
    return true;
}

// std::getline would read a whole binary file that has no '\n' into memory; this stops at
// kMaxHeaderBytes in total. False at the end of the stream or past the limit.
/// "comment run_id <id>\n", or "" without an id; an id must be one word of letters, digits, '-' or '_'.
std::string run_id_comment(const std::string& path, const std::string& run_id) {
    if (run_id.empty()) return "";
    for (char ch : run_id)
        if (!std::isalnum(static_cast<unsigned char>(ch)) && ch != '-' && ch != '_')
            throw std::invalid_argument(path + ": run_id '" + run_id + "': expected letters, digits, '-' or '_'");
    return "comment run_id " + run_id + "\n";
}

bool read_header_line(std::istream& in, std::string& line, std::size_t& header_bytes) {
    line.clear();
    for (int c; (c = in.get()) != std::char_traits<char>::eof();) {
        if (++header_bytes > kMaxHeaderBytes) return false;
        if (c == '\n') return true;
        line.push_back(static_cast<char>(c));
    }
    return !line.empty();
}

std::vector<std::string> split_words(const std::string& line) {
    std::istringstream in(line);
    std::vector<std::string> words;
    for (std::string w; in >> w;) words.push_back(w);
    return words;
}

}  // namespace

void write_particles_ply(const std::string& path, const PlyParticles& p) {
    if (p.dim != 2 && p.dim != 3) {
        throw std::invalid_argument(path + ": dim must be 2 or 3, got " + std::to_string(p.dim));
    }
    const std::size_t n = p.mass.size();
    const std::size_t d = std::size_t(p.dim);
    const std::string why = std::to_string(n) + " particles (mass) x dim " + std::to_string(p.dim);
    check_size(path, "position", p.position.size(), n * d, why);
    check_size(path, "velocity", p.velocity.size(), n * d, why);
    check_size(path, "hardening", p.hardening.size(), n, std::to_string(n) + " particles (mass)");

    std::ostringstream header;
    header << "ply\n"
           << "format binary_little_endian 1.0\n"
           << "comment plasticitynet particles\n"
           << "comment dim " << p.dim << "\n"
           << run_id_comment(path, p.run_id) << "element vertex " << n << "\n";
    for (const char* name : kProperties) header << "property double " << name << "\n";
    header << "end_header\n";

    // The whole vertex block is encoded first so that the stream sees one large write.
    std::string data(n * kVertexBytes, '\0');
    for (std::size_t i = 0; i < n; ++i) {
        char* row = &data[i * kVertexBytes];
        for (std::size_t k = 0; k < 3; ++k) {
            put_le_double(row + 8 * k, k < d ? p.position[i * d + k] : 0.0);
            put_le_double(row + 8 * (3 + k), k < d ? p.velocity[i * d + k] : 0.0);
        }
        put_le_double(row + 48, p.mass[i]);
        put_le_double(row + 56, p.hardening[i]);
    }

    const std::string header_text = header.str();
    write_file_atomically(path, [&](std::ostream& out) {
        out.write(header_text.data(), std::streamsize(header_text.size()));
        out.write(data.data(), std::streamsize(data.size()));
    });
}

PlyParticles read_particles_ply(const std::string& path, int dim) {
    std::string run_id;
    if (dim != 0 && dim != 2 && dim != 3) {
        throw std::invalid_argument(path + ": dim must be 0 (from the file), 2 or 3, got " + std::to_string(dim));
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open for reading: " + std::strerror(errno));
    auto fail = [&](const std::string& problem) { return std::runtime_error(path + ": " + problem); };

    // Header: '\n'-terminated ASCII lines up to "end_header".
    std::size_t header_bytes = 0;
    int line_number = 0;
    int file_dim = 0;
    bool have_format = false, have_vertex = false, ended = false;
    std::uint64_t n = 0;
    std::size_t property = 0;
    for (std::string line; read_header_line(in, line, header_bytes);) {
        ++line_number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        // The offending line is quoted, cut short in case it is binary junk.
        const std::string where = "header line " + std::to_string(line_number) + " '" + line.substr(0, 80) + "': ";
        if (line_number == 1) {
            if (line != "ply") throw fail("not a PLY file (the first line is not 'ply')");
            continue;
        }
        const std::vector<std::string> w = split_words(line);
        if (w.empty()) continue;
        if (w[0] == "format") {
            if (have_format || w.size() != 3 || w[1] != "binary_little_endian" || w[2] != "1.0") {
                throw fail(where + "expected 'format binary_little_endian 1.0' once");
            }
            have_format = true;
        } else if (w[0] == "comment") {
            if (w.size() >= 2 && w[1] == "dim") {
                if (w.size() != 3 || (w[2] != "2" && w[2] != "3")) throw fail(where + "expected 'comment dim 2' or 3");
                file_dim = w[2][0] - '0';
            } else if (w.size() >= 2 && w[1] == "run_id") {
                if (w.size() != 3) throw fail(where + "expected 'comment run_id <id>'");
                run_id = w[2];
            }
        } else if (w[0] == "obj_info") {
            // free text, like comments
        } else if (w[0] == "element") {
            if (have_vertex || w.size() != 3 || w[1] != "vertex" || !parse_count(w[2], n)) {
                throw fail(where + "expected a single 'element vertex <count>'");
            }
            have_vertex = true;
        } else if (w[0] == "property") {
            if (!have_vertex) throw fail(where + "property before 'element vertex'");
            if (property >= kProperties.size()) throw fail(where + "unexpected extra property");
            const char* expected = kProperties[property];
            if (w.size() != 3 || (w[1] != "double" && w[1] != "float64") || w[2] != expected) {
                throw fail(where + "expected 'property double " + expected + "'");
            }
            ++property;
        } else if (w[0] == "end_header") {
            ended = true;
            break;
        } else {
            throw fail(where + "unknown PLY header keyword");
        }
    }
    if (line_number == 0) throw fail("not a PLY file (no 'ply' first line)");
    if (!ended) throw fail("PLY header not terminated by end_header");
    if (!have_format) throw fail("PLY header has no 'format' line");
    if (!have_vertex) throw fail("PLY header has no 'element vertex' line");
    if (property != kProperties.size()) {
        throw fail("PLY header has " + std::to_string(property) + " vertex properties, expected " +
                   std::to_string(kProperties.size()) + " (x y z vx vy vz mass hardening)");
    }
    if (dim == 0) {
        if (file_dim == 0) throw fail("no 'comment dim' line in the header; pass the dimension explicitly");
        dim = file_dim;
    } else if (file_dim != 0 && file_dim != dim) {
        throw fail("the header says dim " + std::to_string(file_dim) + " but dim " + std::to_string(dim) +
                   " was asked for");
    }

    // Vertex data: exactly n rows, so that a truncated frame (or one with trailing bytes, not
    // written by write_particles_ply) is reported rather than read as fewer particles.
    const std::streamoff data_start = in.tellg();
    in.seekg(0, std::ios::end);
    const std::streamoff file_end = in.tellg();
    if (data_start < 0 || file_end < data_start) throw fail("cannot determine the file size");
    const std::uint64_t available = std::uint64_t(file_end - data_start);
    const std::string announced = "the header announces " + std::to_string(n) + " vertices of " +
                                  std::to_string(kVertexBytes) + " bytes but " + std::to_string(available) +
                                  " bytes of vertex data follow";
    if (n > available / kVertexBytes) throw fail("truncated: " + announced);
    if (available != n * kVertexBytes) throw fail("trailing bytes: " + announced);
    std::string data(std::size_t(available), '\0');
    in.seekg(data_start);
    in.read(&data[0], std::streamsize(available));
    if (!in) throw fail("reading the vertex data failed");

    PlyParticles p;
    p.run_id = run_id;
    p.dim = dim;
    const std::size_t d = std::size_t(dim);
    p.position.resize(n * d);
    p.velocity.resize(n * d);
    p.mass.resize(n);
    p.hardening.resize(n);
    for (std::size_t i = 0; i < n; ++i) {
        const char* row = &data[i * kVertexBytes];
        for (std::size_t k = 0; k < 3; ++k) {
            const double x = get_le_double(row + 8 * k);
            const double v = get_le_double(row + 8 * (3 + k));
            if (k < d) {
                p.position[i * d + k] = x;
                p.velocity[i * d + k] = v;
            } else if (x != 0.0 || v != 0.0) {
                throw fail("vertex " + std::to_string(i) + " has z or vz != 0 in a 2D file");
            }
        }
        p.mass[i] = get_le_double(row + 48);
        p.hardening[i] = get_le_double(row + 56);
    }
    return p;
}

namespace {

constexpr std::array<const char*, 6> kMeshVertexProperties = {"x", "y", "z", "vx", "vy", "vz"};
constexpr std::size_t kMeshVertexBytes = 6 * sizeof(double);
constexpr std::size_t kFaceBytes = 1 + 3 * 4 + 8;  // count, three int32 indices, hardening

void put_le_int32(char* dst, std::int32_t value) {
    const auto bits = static_cast<std::uint32_t>(value);
    for (int i = 0; i < 4; ++i) dst[i] = static_cast<char>((bits >> (8 * i)) & 0xff);
}

std::int32_t get_le_int32(const char* src) {
    std::uint32_t bits = 0;
    for (int i = 0; i < 4; ++i) bits |= std::uint32_t(static_cast<unsigned char>(src[i])) << (8 * i);
    return static_cast<std::int32_t>(bits);
}

}  // namespace

void write_mesh_ply(const std::string& path, const PlyMesh& m) {
    if (m.dim != 2 && m.dim != 3) throw std::invalid_argument(path + ": dim must be 2 or 3, got " + std::to_string(m.dim));
    const std::size_t d = static_cast<std::size_t>(m.dim), n = m.position.size() / d, f = m.triangles.size() / 3;
    check_size(path, "position", m.position.size(), d * n, std::to_string(d) + " per node");
    check_size(path, "velocity", m.velocity.size(), d * n, std::to_string(n) + " nodes x " + std::to_string(d));
    check_size(path, "triangles", m.triangles.size(), 3 * f, "3 per triangle");
    check_size(path, "hardening", m.hardening.size(), f, std::to_string(f) + " triangles");
    for (int t : m.triangles)
        if (t < 0 || static_cast<std::size_t>(t) >= n)
            throw std::invalid_argument(path + ": triangle node " + std::to_string(t) + " out of range (" +
                                        std::to_string(n) + " nodes)");
    std::ostringstream header;
    header << "ply\nformat binary_little_endian 1.0\ncomment plasticitynet mesh\ncomment dim " << d << "\n"
           << run_id_comment(path, m.run_id) << "element vertex " << n << "\n";
    for (const char* name : kMeshVertexProperties) header << "property double " << name << "\n";
    header << "element face " << f << "\nproperty list uchar int vertex_indices\nproperty double hardening\nend_header\n";
    std::string data(n * kMeshVertexBytes + f * kFaceBytes, '\0');
    for (std::size_t i = 0; i < n; ++i) {
        char* row = &data[i * kMeshVertexBytes];
        for (std::size_t k = 0; k < 3; ++k) {
            put_le_double(row + 8 * k, k < d ? m.position[d * i + k] : 0.0);
            put_le_double(row + 8 * (3 + k), k < d ? m.velocity[d * i + k] : 0.0);
        }
    }
    for (std::size_t k = 0; k < f; ++k) {
        char* row = &data[n * kMeshVertexBytes + k * kFaceBytes];
        row[0] = 3;
        for (int a = 0; a < 3; ++a) put_le_int32(row + 1 + 4 * a, m.triangles[3 * k + a]);
        put_le_double(row + 13, m.hardening[k]);
    }
    const std::string header_text = header.str();
    write_file_atomically(path, [&](std::ostream& out) {
        out.write(header_text.data(), std::streamsize(header_text.size()));
        out.write(data.data(), std::streamsize(data.size()));
    });
}

PlyMesh read_mesh_ply(const std::string& path) {
    std::string run_id;
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open for reading: " + std::strerror(errno));
    auto fail = [&](const std::string& problem) { return std::runtime_error(path + ": " + problem); };
    // The header must be exactly write_mesh_ply's, comments and obj_info aside.
    std::vector<std::string> expected = {"ply", "format binary_little_endian 1.0", "element vertex #"};
    for (const char* name : kMeshVertexProperties) expected.push_back(std::string("property double ") + name);
    expected.insert(expected.end(), {"element face #", "property list uchar int vertex_indices",
                                     "property double hardening", "end_header"});
    std::uint64_t counts[2] = {0, 0};
    int count_index = 0, line_number = 0, dim = 2;
    std::size_t next = 0, header_bytes = 0;
    for (std::string line; next < expected.size() && read_header_line(in, line, header_bytes);) {
        ++line_number;
        if (!line.empty() && line.back() == '\r') line.pop_back();
        const std::vector<std::string> w = split_words(line);
        if (line_number > 1 && !w.empty() && (w[0] == "comment" || w[0] == "obj_info")) {
            if (w.size() >= 2 && w[1] == "dim") {
                if (w.size() != 3 || (w[2] != "2" && w[2] != "3"))
                    throw fail("header line " + std::to_string(line_number) + ": 'comment dim' must be 2 or 3");
                dim = w[2][0] - '0';
            } else if (w.size() >= 2 && w[1] == "run_id") {
                if (w.size() != 3)
                    throw fail("header line " + std::to_string(line_number) + ": expected 'comment run_id <id>'");
                run_id = w[2];
            }
            continue;
        }
        const std::string& want = expected[next];
        const std::string where = "header line " + std::to_string(line_number) + " '" + line.substr(0, 80) + "': ";
        if (want.back() == '#') {
            const std::vector<std::string> ww = split_words(want);
            if (w.size() != 3 || w[0] != ww[0] || w[1] != ww[1] || !parse_count(w[2], counts[count_index++]))
                throw fail(where + "expected '" + want.substr(0, want.size() - 1) + "<count>'");
        } else if (line != want) {
            throw fail(line_number == 1 ? "not a PLY file (the first line is not 'ply')"
                                        : where + "expected '" + want + "' (a plasticitynet mesh frame)");
        }
        ++next;
    }
    if (next < expected.size()) throw fail("PLY header ends before '" + expected[next] + "'");
    const std::uint64_t n = counts[0], f = counts[1];
    const std::streamoff data_start = in.tellg();
    in.seekg(0, std::ios::end);
    const std::streamoff file_end = in.tellg();
    if (data_start < 0 || file_end < data_start) throw fail("cannot determine the file size");
    const std::uint64_t available = std::uint64_t(file_end - data_start);
    if (n > available / kMeshVertexBytes || f > available / kFaceBytes ||
        available != n * kMeshVertexBytes + f * kFaceBytes)
        throw fail("the header announces " + std::to_string(n) + " vertices and " + std::to_string(f) +
                   " faces but " + std::to_string(available) + " bytes of data follow");
    std::string data(std::size_t(available), '\0');
    in.seekg(data_start);
    in.read(&data[0], std::streamsize(available));
    if (!in) throw fail("reading the data failed");
    PlyMesh m;
    m.run_id = run_id;
    m.dim = dim;
    const std::size_t d = static_cast<std::size_t>(dim);
    m.position.resize(d * n);
    m.velocity.resize(d * n);
    m.triangles.resize(3 * f);
    m.hardening.resize(f);
    for (std::size_t i = 0; i < n; ++i) {
        const char* row = &data[i * kMeshVertexBytes];
        for (std::size_t k = 0; k < d; ++k) {
            m.position[d * i + k] = get_le_double(row + 8 * k);
            m.velocity[d * i + k] = get_le_double(row + 8 * (3 + k));
        }
        if (d == 2 && (get_le_double(row + 16) != 0.0 || get_le_double(row + 40) != 0.0))
            throw fail("vertex " + std::to_string(i) + " has z or vz != 0 in a 2D mesh");
    }
    for (std::size_t k = 0; k < f; ++k) {
        const char* row = &data[n * kMeshVertexBytes + k * kFaceBytes];
        if (row[0] != 3) throw fail("face " + std::to_string(k) + " is not a triangle");
        for (int a = 0; a < 3; ++a) {
            const std::int32_t t = get_le_int32(row + 1 + 4 * a);
            if (t < 0 || static_cast<std::uint64_t>(t) >= n)
                throw fail("face " + std::to_string(k) + " names vertex " + std::to_string(t) + " of " +
                           std::to_string(n));
            m.triangles[3 * k + a] = t;
        }
        m.hardening[k] = get_le_double(row + 13);
    }
    return m;
}

}  // namespace pnet
