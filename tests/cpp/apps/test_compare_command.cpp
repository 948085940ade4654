#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "compare_command.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"

#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using namespace test;  // TempDir, read_file, write_file, expect_error
namespace fs = std::filesystem;

std::string run_json(int dim, const std::string& domain_max = "", double frame_dt = 0.02) {
    const std::string lo = dim == 2 ? "[0, 0]" : "[0, 0, 0]";
    const std::string hi = !domain_max.empty() ? domain_max : dim == 2 ? "[1, 1]" : "[1, 1, 1]";
    std::ostringstream s;
    s << "{\"dim\": " << dim << ", \"domain_min\": " << lo << ", \"domain_max\": " << hi
      << ", \"dx\": 0.015625, \"frame_dt\": " << frame_dt
      << ", \"scene\": \"block.json\", \"integrator\": \"explicit\", \"dt\": 1e-5}\n";
    return s.str();
}

/// A square (cube) of 64^dim particles with lower corner (cx, cy[, cz]) and side 0.25 m: 4 per 1/64 m cell side.
PlyParticles block(int dim, double cx, double cy, double cz = 0.25) {
    PlyParticles p;
    p.dim = dim;
    const int n = 64;  // per axis
    const double h = 0.25 / n;
    for (int k = 0; k < (dim == 3 ? n : 1); ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                p.position.push_back(cx + (i + 0.5) * h);
                p.position.push_back(cy + (j + 0.5) * h);
                if (dim == 3) p.position.push_back(cz + (k + 0.5) * h);
                for (int a = 0; a < dim; ++a) p.velocity.push_back(0.0);
                p.mass.push_back(1e-3);
                p.hardening.push_back(0.0);
            }
    return p;
}

std::string frame_path(const std::string& dir, int frame) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.ply", frame);
    return (fs::path(dir) / name).string();
}

/// A run directory with run.json and the given frames of a block falling by 0.05 m per frame, shifted right by
/// shift(frame) m.
template <typename Shift>
std::string make_run(const TempDir& tmp, const std::string& name, int dim, const std::vector<int>& frames,
                     Shift shift) {
    const std::string dir = tmp.file(name);
    fs::create_directories(dir);
    write_file((fs::path(dir) / "run.json").string(), run_json(dim));
    for (int f : frames) write_particles_ply(frame_path(dir, f), block(dim, 0.3 + shift(f), 0.5 - 0.05 * f));
    return dir;
}

std::string make_run(const TempDir& tmp, const std::string& name, int dim, const std::vector<int>& frames) {
    return make_run(tmp, name, dim, frames, [](int) { return 0.0; });
}

struct Result {
    int code;
    std::string out, err;
};

/// Runs `pnet compare args...`, capturing stdout and stderr.
Result compare(std::vector<std::string> args) {
    args.insert(args.begin(), "compare");
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    testing::internal::CaptureStdout();
    testing::internal::CaptureStderr();
    const int code = apps::compare_command(static_cast<int>(args.size()), argv.data());
    Result r{code, "", ""};
    r.out = testing::internal::GetCapturedStdout();
    r.err = testing::internal::GetCapturedStderr();
    return r;
}

struct CsvRow {
    int frame;
    double time, soft, binary, plasticinelab, soft_coarse, spread_a, spread_b, height_a, height_b;
};

std::vector<CsvRow> read_csv(const std::string& path) {
    std::istringstream in(read_file(path));
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line,
              "frame,time_s,soft_iou,binary_iou,plasticinelab_iou,soft_iou_coarse,spread_a_m,spread_b_m,height_a_m,"
              "height_b_m");
    std::vector<CsvRow> rows;
    while (std::getline(in, line)) {
        CsvRow r{};
        char comma[9];
        std::istringstream s(line);
        s >> r.frame >> comma[0] >> r.time >> comma[1] >> r.soft >> comma[2] >> r.binary >> comma[3] >>
            r.plasticinelab >> comma[4] >> r.soft_coarse >> comma[5] >> r.spread_a >> comma[6] >> r.spread_b >>
            comma[7] >> r.height_a >> comma[8] >> r.height_b;
        bool commas = true;
        for (char c : comma) commas = commas && c == ',';
        EXPECT_TRUE(s && commas) << line;
        rows.push_back(r);
    }
    return rows;
}

TEST(CompareCommand, IdenticalRunsHaveBinaryIouOne) {
    TempDir tmp;
    const std::string a = make_run(tmp, "run_a", 2, {0, 1, 2});
    const std::string b = make_run(tmp, "run_b", 2, {0, 1, 2});
    const Result r = compare({a, b});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.err, "");

    // Default output: DIR_B/compare_<basename of DIR_A>.
    const std::string out = (fs::path(b) / "compare_run_a").string();
    const std::vector<CsvRow> rows = read_csv(out + "/iou.csv");
    ASSERT_EQ(rows.size(), 3u);
    for (int f = 0; f < 3; ++f) {
        EXPECT_EQ(rows[f].frame, f);
        EXPECT_DOUBLE_EQ(rows[f].time, 0.02 * f);
        EXPECT_EQ(rows[f].binary, 1.0);
        EXPECT_EQ(rows[f].soft, 1.0);
        EXPECT_EQ(rows[f].soft_coarse, 1.0);
        EXPECT_EQ(rows[f].spread_a, rows[f].spread_b);
        EXPECT_GT(rows[f].spread_a, 0.0);
        EXPECT_EQ(rows[f].height_a, rows[f].height_b);
        // PlasticineLab's self-IoU is below 1 (the B-spline rim of the block), but a solid block is mostly full nodes.
        EXPECT_GT(rows[f].plasticinelab, 0.8);
        EXPECT_LT(rows[f].plasticinelab, 1.0);
    }
    const Image plot = read_png_rgb(out + "/iou.png");
    EXPECT_EQ(plot.width, 800);
    EXPECT_EQ(plot.height, 500);

    EXPECT_NE(r.out.find("compared 3 frames (0-2)"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find("binary IoU: min 1.0000 at frame 0"), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(out + "/iou.csv"), std::string::npos) << r.out;
}

TEST(CompareCommand, TrailingSlashAndThreeDimensions) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a3", 3, {0, 1});
    const std::string b = make_run(tmp, "b3", 3, {0, 1});
    const Result r = compare({a + "/", b, "--dx", "0.03125"});
    ASSERT_EQ(r.code, 0) << r.err;
    const std::vector<CsvRow> rows = read_csv((fs::path(b) / "compare_a3" / "iou.csv").string());
    ASSERT_EQ(rows.size(), 2u);
    for (const CsvRow& row : rows) EXPECT_EQ(row.binary, 1.0);
}

TEST(CompareCommand, ShiftedBlockLowersIou) {
    TempDir tmp;
    const std::string a = make_run(tmp, "ref", 2, {0, 1, 2, 3});
    // B's block drifts right by 0.04 m per frame (a sixth of its side).
    const std::string b = make_run(tmp, "drift", 2, {0, 1, 2, 3}, [](int f) { return 0.04 * f; });
    const std::string out = tmp.file("report");
    const Result r = compare({a, b, "--out", out, "--dx", "0.0078125"});
    ASSERT_EQ(r.code, 0) << r.err;
    const std::vector<CsvRow> rows = read_csv(out + "/iou.csv");
    ASSERT_EQ(rows.size(), 4u);
    EXPECT_EQ(rows[0].binary, 1.0);
    for (int f = 1; f < 4; ++f) {
        EXPECT_LT(rows[f].soft, rows[f - 1].soft) << f;
        EXPECT_LT(rows[f].binary, rows[f - 1].binary) << f;
    }
    // Overlap of two 0.25 m squares offset by 0.12 m: 0.13 / 0.37 of the union, about 0.35.
    EXPECT_NEAR(rows[3].binary, 0.13 / 0.37, 0.05);
    EXPECT_NE(r.out.find("soft IoU:   min"), std::string::npos);
    EXPECT_NE(r.out.find("at frame 3 (t = 0.06 s)"), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_ref"));
}

TEST(CompareCommand, ComparesCommonFramesAndWarnsAboutTheRest) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0, 1, 2, 3, 4});
    const std::string b = make_run(tmp, "b", 2, {0, 1, 2, 7});
    write_file(frame_path(b, 5) + ".tmp.123", "half-written");  // an interrupted atomic write is not a frame
    const Result r = compare({a, b});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_NE(r.err.find("frames only in " + a + ", not compared: 3-4"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("frames only in " + b + ", not compared: 7"), std::string::npos) << r.err;
    EXPECT_EQ(read_csv(b + "/compare_a/iou.csv").size(), 3u);
}

TEST(CompareCommand, MissingDirectory) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0});
    const std::string missing = tmp.file("nope");
    const Result r = compare({a, missing});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(missing + ": no such directory"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(missing));
}

TEST(CompareCommand, MissingOrBadRunJson) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0});
    const std::string b = make_run(tmp, "b", 2, {0});
    const std::string json = (fs::path(b) / "run.json").string();

    fs::remove(json);
    Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(json), std::string::npos) << r.err;

    write_file(json, "{\"dim\": 2, \"domain_min\": [0, 0], \"domain_max\": [1, 1], \"dx\": 0.01}");
    r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(json + ": missing \"frame_dt\""), std::string::npos) << r.err;

    write_file(json, "{\"dim\": 2, \"domain_min\": [0, 0], \"domain_max\": [1], \"dx\": 0.01, \"frame_dt\": 0.02}");
    r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(json + ": domain_max"), std::string::npos) << r.err;

    write_file(json, "{\"dim\": 2,");
    r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(json + ": not valid JSON"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_a"));
}

TEST(CompareCommand, MismatchedDimension) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0});
    const std::string b = make_run(tmp, "b", 3, {0});
    const Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(b + "/run.json: dim is 3 but " + a + "/run.json has 2"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_a"));
}

TEST(CompareCommand, MismatchedDomainOrFrameInterval) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0});
    const std::string b = make_run(tmp, "b", 2, {0});
    write_file(b + "/run.json", run_json(2, "[1, 2]"));
    Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(b + "/run.json: domain_max is [1.0,2.0]"), std::string::npos) << r.err;

    write_file(b + "/run.json", run_json(2, "", 0.01));
    r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(b + "/run.json: frame_dt is 0.01"), std::string::npos) << r.err;
}

TEST(CompareCommand, NoCommonFrames) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0, 1});
    const std::string b = make_run(tmp, "b", 2, {2, 3});
    const Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("no frame_NNNNN.ply present in both " + a + " (0-1) and " + b + " (2-3)"),
              std::string::npos)
        << r.err;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_a"));

    const std::string empty = tmp.file("empty");
    fs::create_directories(empty);
    write_file(empty + "/run.json", run_json(2));
    EXPECT_EQ(compare({a, empty}).code, 2);
}

TEST(CompareCommand, UnreadableFrame) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0, 1});
    const std::string b = make_run(tmp, "b", 2, {0, 1});
    write_file(frame_path(b, 1), "not a ply file");
    Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(frame_path(b, 1) + ": "), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_a")) << "no partial result";

    // A 3D frame in a 2D run contradicts run.json.
    write_particles_ply(frame_path(b, 1), block(3, 0.3, 0.3));
    r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(frame_path(b, 1) + ": "), std::string::npos) << r.err;
}

TEST(CompareCommand, FramesFromAnotherRunAreRefused) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0, 1});
    const std::string b = tmp.file("b");
    fs::create_directories(b);
    std::string json = run_json(2);
    json.insert(1, "\"run_id\": \"00000000000000bb\", ");
    write_file((fs::path(b) / "run.json").string(), json);
    PlyParticles frame = block(2, 0.3, 0.5);
    frame.run_id = "00000000000000bb";
    write_particles_ply(frame_path(b, 0), frame);
    frame.run_id = "00000000000000cc";  // left behind by an earlier run
    write_particles_ply(frame_path(b, 1), frame);
    Result r = compare({a, b});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find(frame_path(b, 1) + ": not written by the run in"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("00000000000000cc"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(fs::path(b) / "compare_a")) << "no partial result";

    frame.run_id = "00000000000000bb";  // all frames from the run: compared
    write_particles_ply(frame_path(b, 1), frame);
    r = compare({a, b});
    EXPECT_EQ(r.code, 0) << r.err;
}

/// A FEM (or coupled) run: run.json with meshes, and per frame a 2D mesh of two triangles (the unit square
/// at (x0, 0), side `side`), its nodes moved by shift(frame) along x in run B. A coupled run also writes
/// particles: one at the square's centre (inside) and one far from it.
std::string make_mesh_run(const TempDir& tmp, const std::string& name, bool coupled, const std::vector<int>& frames,
                          double shift, double side = 0.1) {
    const std::string dir = tmp.file(name);
    fs::create_directories(dir);
    std::ostringstream json;
    json << "{\"dim\": 2, \"domain_min\": [0, 0], \"domain_max\": [1, 1], \"frame_dt\": 0.02, \"elements\": 2, "
         << (coupled ? "\"particles\": 2, \"dx\": 0.015625" : "\"mesh_first_node\": [0, 4], \"bbox_diagonal\": 0.5")
         << "}\n";
    write_file((fs::path(dir) / "run.json").string(), json.str());
    for (int f : frames) {
        PlyMesh m;
        m.dim = 2;
        const double x0 = 0.4 + shift * f;
        m.position = {x0, 0.2, x0 + side, 0.2, x0 + side, 0.2 + side, x0, 0.2 + side};
        m.velocity.assign(8, 0.0);
        m.triangles = {0, 1, 2, 0, 2, 3};
        m.hardening = {0.0, 0.0};
        std::string path = frame_path(dir, f);
        if (coupled) {
            PlyParticles p;
            p.dim = 2;
            p.position = {x0 + side / 2, 0.2 + side / 2, 0.9, 0.9};
            p.velocity.assign(4, 0.0);
            p.mass = {1e-3, 1e-3};
            p.hardening = {0.0, 0.0};
            write_particles_ply(path, p);
            path = path.substr(0, path.size() - 4) + "_mesh.ply";
        }
        write_mesh_ply(path, m);
    }
    return dir;
}

// FEM runs: the first mesh's nodes, node by node, in m and % of run A's bbox_diagonal (docs/metrics.md).
TEST(CompareCommand, MeshRunsGiveTheNodalDistance) {
    TempDir tmp;
    const std::string a = make_mesh_run(tmp, "fem_a", false, {0, 1, 2}, 0.0);
    const std::string b = make_mesh_run(tmp, "fem_b", false, {0, 1, 2}, 0.01);
    const Result r = compare({a, b, "--out", tmp.file("out")});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(read_file(tmp.file("out") + "/nodal.csv"),
              "frame,time_s,mean_m,max_m,mean_pct,max_pct,size_m\n"
              "0,0,0,0,0,0,0.5\n"
              "1,0.02,0.01,0.01,2,2,0.5\n"
              "2,0.04,0.02,0.02,4,4,0.5\n");
    EXPECT_FALSE(fs::exists(tmp.file("out") + "/iou.csv"));
    EXPECT_NE(r.out.find("body (4 nodes, size 0.5 m): nodal distance at frame 2 mean 0.02 m (4.000%)"),
              std::string::npos)
        << r.out;
    // A FEM run is not compared with an MPM one.
    const std::string mpm = make_run(tmp, "mpm", 2, {0, 1, 2});
    const Result mixed = compare({a, mpm});
    EXPECT_EQ(mixed.code, 2);
    EXPECT_NE(mixed.err.find("what the frames hold is particles but"), std::string::npos) << mixed.err;
}

// Coupled runs: the particles' IoU, the body's nodal distance (its size from A's first frame) and the
// particles inside it.
TEST(CompareCommand, CoupledRunsGiveIouNodalDistanceAndParticlesInside) {
    TempDir tmp;
    const std::string a = make_mesh_run(tmp, "cpl_a", true, {0, 1}, 0.0);
    const std::string b = make_mesh_run(tmp, "cpl_b", true, {0, 1}, 0.05);
    const Result r = compare({a, b, "--out", tmp.file("out")});
    ASSERT_EQ(r.code, 0) << r.err;
    EXPECT_TRUE(fs::exists(tmp.file("out") + "/iou.csv"));
    const std::string nodal = read_file(tmp.file("out") + "/nodal.csv");
    EXPECT_EQ(nodal.substr(0, nodal.find('\n')), "frame,time_s,mean_m,max_m,mean_pct,max_pct,size_m,penetrations");
    EXPECT_NE(nodal.find("\n1,0.02,0.05,0.05,"), std::string::npos) << nodal;  // 0.05 m of a 0.1414 m square
    EXPECT_NE(nodal.find(",35.3553391,35.3553391,0.141421356,1\n"), std::string::npos) << nodal;
    EXPECT_NE(r.out.find("particles inside the body: at most 1 in a frame"), std::string::npos) << r.out;
}

TEST(CompareCommand, UsageErrors) {
    TempDir tmp;
    const std::string a = make_run(tmp, "a", 2, {0});
    for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
             {}, {a}, {a, a, a}, {a, a, "--frobnicate"}, {a, a, "--dx"}, {a, a, "--dx", "0"}, {a, a, "--dx", "x"},
             {a, a, "--dx", "1e-3x"}, {a, a, "--out"}}) {
        const Result r = compare(args);
        EXPECT_EQ(r.code, 2);
        EXPECT_NE(r.err.find("usage: pnet compare DIR_A DIR_B"), std::string::npos) << r.err;
    }
    // A grid too fine to hold in memory is refused before any frame is read.
    const Result r = compare({a, a, "--dx", "1e-6"});
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("choose a coarser --dx"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace pnet
