#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"

#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using namespace test;  // TempDir, read_file, write_file, expect_error
namespace fs = std::filesystem;

/// n particles with seeded random fields, plus values that a lossy or text encoding would alter
/// (a subnormal, the largest double, 1/3, -0 in the velocity).
PlyParticles random_particles(int dim, std::size_t n, unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    PlyParticles p;
    p.dim = dim;
    for (std::size_t i = 0; i < n * std::size_t(dim); ++i) {
        p.position.push_back(u(rng));
        p.velocity.push_back(10 * u(rng));
    }
    for (std::size_t i = 0; i < n; ++i) {
        p.mass.push_back(1e-6 * (1.5 + u(rng)));
        p.hardening.push_back(u(rng) > 0 ? 0.0 : 1e3 * u(rng));
    }
    if (n >= 2) {
        p.position[0] = std::numeric_limits<double>::denorm_min();
        p.position[1] = std::numeric_limits<double>::max();
        p.velocity[0] = -0.0;
        p.mass[1] = 1.0 / 3.0;
    }
    return p;
}

void expect_bit_equal(const std::vector<double>& a, const std::vector<double>& b, const char* field) {
    ASSERT_EQ(a.size(), b.size()) << field;
    EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(double)), 0) << field << " differs";
}

class PlyDim : public ::testing::TestWithParam<int> {};

TEST_P(PlyDim, RoundTripIsBitExact) {
    const int dim = GetParam();
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    const PlyParticles p = random_particles(dim, 257, 7u + unsigned(dim));
    write_particles_ply(path, p);

    for (int asked : {0, dim}) {
        const PlyParticles q = read_particles_ply(path, asked);
        EXPECT_EQ(q.dim, dim);
        EXPECT_EQ(q.size(), p.size());
        expect_bit_equal(q.position, p.position, "position");
        expect_bit_equal(q.velocity, p.velocity, "velocity");
        expect_bit_equal(q.mass, p.mass, "mass");
        expect_bit_equal(q.hardening, p.hardening, "hardening");
    }
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"frame.ply"});  // no temporary file left
}

TEST_P(PlyDim, HeaderAndLittleEndianLayout) {
    const int dim = GetParam();
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    PlyParticles p;
    p.dim = dim;
    p.position.assign(std::size_t(3 * dim), 0.0);
    p.position[0] = 1.0;  // x of particle 0
    p.velocity.assign(std::size_t(3 * dim), 0.0);
    p.mass = {2.0, 2.0, 2.0};
    p.hardening = {0.0, 0.0, 0.0};
    write_particles_ply(path, p);

    const std::string header =
        "ply\n"
        "format binary_little_endian 1.0\n"
        "comment plasticitynet particles\n"
        "comment dim " +
        std::to_string(dim) +
        "\n"
        "element vertex 3\n"
        "property double x\n"
        "property double y\n"
        "property double z\n"
        "property double vx\n"
        "property double vy\n"
        "property double vz\n"
        "property double mass\n"
        "property double hardening\n"
        "end_header\n";
    const std::string bytes = read_file(path);
    ASSERT_EQ(bytes.size(), header.size() + 3 * 8 * 8);
    EXPECT_EQ(bytes.substr(0, header.size()), header);
    // 1.0 is 0x3FF0000000000000: least significant byte first; mass 2.0 = 0x4000000000000000 at offset 48.
    EXPECT_EQ(bytes.substr(header.size(), 8), std::string("\x00\x00\x00\x00\x00\x00\xf0\x3f", 8));
    EXPECT_EQ(bytes.substr(header.size() + 48, 8), std::string("\x00\x00\x00\x00\x00\x00\x00\x40", 8));
}

TEST_P(PlyDim, TruncatedFileIsRejected) {
    const int dim = GetParam();
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    write_particles_ply(path, random_particles(dim, 10, 3));
    const std::string bytes = read_file(path);
    write_file(path, bytes.substr(0, bytes.size() - 5));
    expect_error<std::runtime_error>([&] { read_particles_ply(path, 0); }, path, "truncated");
    write_file(path, bytes.substr(0, bytes.size() - 10 * 64));  // header only
    expect_error<std::runtime_error>([&] { read_particles_ply(path, 0); }, path, "truncated");
    write_file(path, bytes + "x");
    expect_error<std::runtime_error>([&] { read_particles_ply(path, 0); }, path, "trailing bytes");
}

TEST_P(PlyDim, EmptyFrameRoundTrips) {
    TempDir dir;
    const std::string path = dir.file("empty.ply");
    PlyParticles p;
    p.dim = GetParam();
    write_particles_ply(path, p);
    const PlyParticles q = read_particles_ply(path);
    EXPECT_EQ(q.dim, GetParam());
    EXPECT_EQ(q.size(), 0u);
    EXPECT_TRUE(q.position.empty());
}

INSTANTIATE_TEST_SUITE_P(Dims, PlyDim, ::testing::Values(2, 3),
                         [](const auto& param) { return std::to_string(param.param) + "d"; });

TEST(Ply, DimensionMismatchIsRejected) {
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    write_particles_ply(path, random_particles(3, 4, 1));
    expect_error<std::runtime_error>([&] { read_particles_ply(path, 2); }, path, "dim 3");
}

TEST(Ply, NonPlyFilesAreRejected) {
    TempDir dir;
    const std::string text = dir.file("notes.txt");
    write_file(text, "hello world\n");
    expect_error<std::runtime_error>([&] { read_particles_ply(text); }, text, "not a PLY file");

    // Binary data without any newline must not be read whole as one "line".
    const std::string binary = dir.file("noise.bin");
    write_file(binary, std::string(1 << 20, '\x01'));
    expect_error<std::runtime_error>([&] { read_particles_ply(binary); }, binary, "not a PLY file");

    const std::string empty = dir.file("empty.ply");
    write_file(empty, "");
    expect_error<std::runtime_error>([&] { read_particles_ply(empty); }, empty, "not a PLY file");

    const std::string missing = dir.file("missing.ply");
    expect_error<std::runtime_error>([&] { read_particles_ply(missing); }, missing, "cannot open");
}

TEST(Ply, ForeignHeadersAreRejected) {
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    write_particles_ply(path, random_particles(2, 2, 5));
    const std::string good = read_file(path);
    auto with = [&](const std::string& from, const std::string& to) {
        std::string s = good;
        s.replace(s.find(from), from.size(), to);
        write_file(path, s);
    };
    with("binary_little_endian", "ascii");
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "binary_little_endian 1.0");
    with("property double mass", "property float mass");
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "property double mass");
    with("property double vx", "property double nx");
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "property double vx");
    with("comment dim 2\n", "");
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "comment dim");
    EXPECT_EQ(read_particles_ply(path, 2).size(), 2u);  // without the comment, an explicit dim reads it
    with("end_header\n", "end_headr\n");
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "end_headr");
}

TEST(Ply, NonzeroZInA2dFileIsRejected) {
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    write_particles_ply(path, random_particles(3, 4, 2));
    std::string bytes = read_file(path);
    bytes.replace(bytes.find("comment dim 3"), 13, "comment dim 2");
    write_file(path, bytes);
    expect_error<std::runtime_error>([&] { read_particles_ply(path); }, path, "z or vz");
}

TEST(Ply, WriterChecksSizes) {
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    PlyParticles p = random_particles(2, 3, 4);
    p.velocity.pop_back();
    expect_error<std::invalid_argument>([&] { write_particles_ply(path, p); }, path, "velocity has 5 values");
    p = random_particles(2, 3, 4);
    p.dim = 4;
    expect_error<std::invalid_argument>([&] { write_particles_ply(path, p); }, path, "dim");
    EXPECT_FALSE(fs::exists(path));
}

// write_file_atomically is what makes every frame and image writer safe; tested here, beside its
// main user.
TEST(Ply, RunIdRoundTripsInParticleAndMeshFrames) {
    TempDir dir;
    PlyParticles p = random_particles(2, 5, 11u);
    write_particles_ply(dir.file("untagged.ply"), p);
    EXPECT_EQ(read_particles_ply(dir.file("untagged.ply")).run_id, "");
    p.run_id = "9f3e0c21aa7d4b10";
    write_particles_ply(dir.file("tagged.ply"), p);
    const PlyParticles q = read_particles_ply(dir.file("tagged.ply"), 2);
    EXPECT_EQ(q.run_id, p.run_id);
    expect_bit_equal(q.position, p.position, "position");
    EXPECT_NE(read_file(dir.file("tagged.ply")).find("comment run_id 9f3e0c21aa7d4b10\n"), std::string::npos);

    PlyMesh m;
    m.dim = 2;
    m.position = {0, 0, 1, 0, 0, 1};
    m.velocity = {0, 0, 0, 0, 0, 0};
    m.triangles = {0, 1, 2};
    m.hardening = {0.05};
    m.run_id = "run-2";
    write_mesh_ply(dir.file("mesh.ply"), m);
    EXPECT_EQ(read_mesh_ply(dir.file("mesh.ply")).run_id, "run-2");

    p.run_id = "two words";  // one header word only
    expect_error<std::invalid_argument>([&] { write_particles_ply(dir.file("bad.ply"), p); }, dir.file("bad.ply"),
                                        "run_id");
    EXPECT_FALSE(fs::exists(dir.file("bad.ply")));
}

TEST(AtomicFile, ReplacesTheFileAndLeavesNoTemporary) {
    TempDir dir;
    const std::string path = dir.file("out.txt");
    write_text_atomically(path, "first");
    write_text_atomically(path, "second, longer");
    EXPECT_EQ(read_file(path), "second, longer");
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFile, ThrowingWriterLeavesTheOldFileIntact) {
    TempDir dir;
    const std::string path = dir.file("frame.ply");
    const std::string old_content = "the previous frame";
    write_file(path, old_content);
    expect_error<std::runtime_error>(
        [&] {
            write_file_atomically(path, [](std::ostream& out) {
                out << std::string(100000, 'x');  // more than a stream buffer: some bytes reach the disk
                out.flush();
                throw std::runtime_error("simulated failure");
            });
        },
        path, "simulated failure");
    EXPECT_EQ(read_file(path), old_content);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"frame.ply"});

    // Without an old file, none appears.
    const std::string fresh = dir.file("fresh.ply");
    EXPECT_THROW(write_file_atomically(fresh, [](std::ostream&) { throw 42; }), std::runtime_error);
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"frame.ply"});
}

TEST(AtomicFile, FailedStreamLeavesTheOldFileIntact) {
    TempDir dir;
    const std::string path = dir.file("out.txt");
    write_file(path, "old");
    expect_error<std::runtime_error>(
        [&] {
            write_file_atomically(path, [](std::ostream& out) {
                out << "partial";
                out.setstate(std::ios::badbit);  // as a failed write (e.g. disk full) would
            });
        },
        path, "failed");
    EXPECT_EQ(read_file(path), "old");
    EXPECT_EQ(dir.entries(), std::vector<std::string>{"out.txt"});
}

TEST(AtomicFile, MissingFolderIsReported) {
    TempDir dir;
    const std::string path = dir.file("no/such/folder/out.txt");
    expect_error<std::runtime_error>([&] { write_text_atomically(path, "x"); }, path, "cannot create");
}

}  // namespace
}  // namespace pnet
