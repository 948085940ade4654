// 3D FEM meshes: gmsh's tetrahedral shapes (volumes, closed and outward boundaries,
// determinism, bad shapes), closed surfaces tetrahedralized, and the 3D outputs
// (mesh PLY round trip, VTU structure, the shaded render).
#include <gtest/gtest.h>

#include <Eigen/Geometry>  // cross()
#include <cmath>
#include <fstream>
#include <map>

#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/render.hpp"
#include "pnet/io/vtu.hpp"
#include "support/fem_systems.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

double total_volume(const Mesh<3>& m) {
    double v = 0.0;
    for (std::size_t e = 0; e < m.elements.size(); ++e) {
        const double ve = m.signed_volume(m.x, e);
        EXPECT_GT(ve, 0.0) << "element " << e;
        v += ve;
    }
    return v;
}

/// The volume the boundary triangles enclose (divergence theorem: positive for outward
/// normals), and whether every boundary edge is shared by exactly two boundary triangles.
std::pair<double, bool> enclosed_volume_and_closed(const Mesh<3>& m) {
    double volume = 0.0;
    std::map<std::pair<int, int>, int> edges;
    for (const auto& f : m.boundary) {
        const Vec<3>&a = m.x[f[0]], &b = m.x[f[1]], &c = m.x[f[2]];
        volume += a.dot(b.cross(c)) / 6.0;
        for (int k = 0; k < 3; ++k) ++edges[{std::min(f[k], f[(k + 1) % 3]), std::max(f[k], f[(k + 1) % 3])}];
    }
    bool closed = true;
    for (const auto& [edge, count] : edges) closed = closed && count == 2;
    return {volume, closed};
}

Shape3d frame(double size) {
    Shape3d s;
    s.kind = Shape3d::Kind::Frame;
    s.min = Vec<3>(0.45, 0.0003, 0.48);
    s.max = Vec<3>(0.55, 0.1803, 0.52);
    s.thickness = 0.012;
    s.element_size = size;
    return s;
}

TEST(Mesh3d, ShapesHaveTheirVolumeAndAClosedOutwardBoundary) {
    const Shape3d box = test::box_shape<3>(Vec<3>(0.0, 0.0, 0.0), Vec<3>(0.02, 0.03, 0.04), 0.01);
    Shape3d sphere;
    sphere.kind = Shape3d::Kind::Sphere;
    sphere.center = Vec<3>(0.5, 0.5, 0.5);
    sphere.radius = 0.05;
    sphere.element_size = 0.01;
    const double frame_volume = 0.1 * 0.18 * 0.04 - 0.076 * 0.156 * 0.04;
    const std::vector<std::tuple<std::string, Shape3d, double, double>> cases = {
        {"box", box, 0.02 * 0.03 * 0.04, 1e-12},
        {"frame", frame(0.015), frame_volume, 1e-12},
        {"sphere", sphere, 4.0 / 3.0 * M_PI * std::pow(0.05, 3), 0.05},  // inscribed polyhedron: a few % less
    };
    for (const auto& [name, shape, volume, tolerance] : cases) {
        SCOPED_TRACE(name);
        const Mesh<3> m = mesh_shape(shape, name);
        EXPECT_GT(m.elements.size(), 5u);
        EXPECT_NEAR(total_volume(m), volume, tolerance * volume);
        const auto [enclosed, closed] = enclosed_volume_and_closed(m);
        EXPECT_TRUE(closed) << "every boundary edge in two boundary triangles";
        EXPECT_NEAR(enclosed, total_volume(m), 1e-9 * volume) << "outward-oriented boundary";
    }
}

TEST(Mesh3d, GmshIsDeterministicAndBadShapesAreRefused) {
    const Mesh<3> a = mesh_shape(frame(0.015), "frame"), b = mesh_shape(frame(0.015), "frame");
    ASSERT_EQ(a.nodes(), b.nodes());
    EXPECT_EQ(a.elements, b.elements);
    for (std::size_t i = 0; i < a.nodes(); ++i) EXPECT_EQ(a.x[i], b.x[i]);
    Shape3d no_hole = frame(0.015);
    no_hole.thickness = 0.05;
    test::expect_error<MeshError>([&] { mesh_shape(no_hole, "scene.json: meshes[0]"); }, "scene.json: meshes[0]",
                                  "leave a hole");
    Shape3d flat = frame(0.015);
    flat.max[2] = flat.min[2];
    test::expect_error<MeshError>([&] { mesh_shape(flat, "m"); }, "m", "max > min on every axis");
    Shape3d huge = frame(1.0);
    test::expect_error<MeshError>([&] { mesh_shape(huge, "m"); }, "m", "element_size");
}

TEST(Mesh3d, ClosedObjSurfaceIsTetrahedralizedAndBadOnesAreRefused) {
    test::TempDir dir;
    // A 2 cm cube: 8 vertices, 6 quads (fan-triangulated), counter-clockwise seen from outside.
    std::ofstream(dir.file("cube.obj")) << "# cube\nv 0 0 0\nv 0.02 0 0\nv 0.02 0.02 0\nv 0 0.02 0\n"
                                           "v 0 0 0.02\nv 0.02 0 0.02\nv 0.02 0.02 0.02\nv 0 0.02 0.02\n"
                                           "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";
    const Mesh<3> m = tetrahedralize_surface_file(dir.file("cube.obj"), 0.005);
    EXPECT_GT(m.elements.size(), 20u);
    EXPECT_NEAR(total_volume(m), 8e-6, 1e-12);
    EXPECT_TRUE(enclosed_volume_and_closed(m).second);
    std::ofstream(dir.file("none.obj")) << "v 0 0 0\nv 1 0 0\n";
    test::expect_error<MeshError>([&] { tetrahedralize_surface_file(dir.file("none.obj"), 0.1); },
                                  dir.file("none.obj"), "no faces");
    std::ofstream(dir.file("bad.obj")) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n";
    test::expect_error<MeshError>([&] { tetrahedralize_surface_file(dir.file("bad.obj"), 0.1); },
                                  dir.file("bad.obj"), "out of range");
    test::expect_error<MeshError>([&] { tetrahedralize_surface_file(dir.file("missing.obj"), 0.1); },
                                  dir.file("missing.obj"), "no such surface file");
}

TEST(Mesh3d, FramesRoundTripThroughPlyAndWriteVtuAndARender) {
    const Mesh<3> m = mesh_shape(frame(0.015), "frame");
    test::TempDir dir;
    PlyMesh ply;
    ply.dim = 3;
    for (const Vec<3>& p : m.x)
        for (int a = 0; a < 3; ++a) {
            ply.position.push_back(p[a]);
            ply.velocity.push_back(0.1 * a);
        }
    for (const auto& f : m.boundary) {
        ply.triangles.insert(ply.triangles.end(), f.begin(), f.end());
        ply.hardening.push_back(0.05);
    }
    write_mesh_ply(dir.file("f.ply"), ply);
    const PlyMesh back = read_mesh_ply(dir.file("f.ply"));
    EXPECT_EQ(back.dim, 3);
    EXPECT_EQ(back.position, ply.position);
    EXPECT_EQ(back.velocity, ply.velocity);
    EXPECT_EQ(back.triangles, ply.triangles);

    VtuMesh vtu;
    vtu.dim = 3;
    vtu.position = ply.position;
    for (const auto& el : m.elements) vtu.cells.insert(vtu.cells.end(), el.begin(), el.end());
    vtu.point_data.push_back({"velocity", 3, ply.velocity});
    vtu.cell_data.push_back({"hardening", 1, std::vector<double>(m.elements.size(), 0.05)});
    write_vtu(dir.file("f.vtu"), vtu);
    const std::string text = test::read_file(dir.file("f.vtu"));
    EXPECT_NE(text.find("NumberOfPoints=\"" + std::to_string(m.nodes()) + "\" NumberOfCells=\"" +
                        std::to_string(m.elements.size()) + "\""),
              std::string::npos);
    EXPECT_NE(text.find("Name=\"hardening\""), std::string::npos);
    std::size_t tets = 0;
    for (std::size_t at = text.find("\n10 "); at != std::string::npos; at = text.find(" 10 ", at + 1)) ++tets;
    EXPECT_GT(tets, 0u) << "VTK_TETRA cells";
    vtu.cell_data[0].values.pop_back();
    test::expect_error<std::invalid_argument>([&] { write_vtu(dir.file("g.vtu"), vtu); }, dir.file("g.vtu"),
                                              "field hardening has");

    ParticleRenderOptions r;
    const double lo[3] = {0.34, -0.01, 0.38}, hi[3] = {0.66, 0.23, 0.62};
    for (int a = 0; a < 3; ++a) {
        r.domain_min[a] = lo[a];
        r.domain_max[a] = hi[a];
    }
    r.width_px = 200;
    const Image image = render_mesh_3d(ply.position, ply.triangles, {}, r);
    int coloured = 0;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) {
            const Rgb c = image.get(x, y);
            coloured += !(c.r == c.g && c.g == c.b);  // not white, grey or black: the shaded surface
        }
    EXPECT_GT(coloured, image.width * image.height / 50);
    const Image again = render_mesh_3d(ply.position, ply.triangles, {}, r);
    EXPECT_EQ(again.rgb, image.rgb);
}

}  // namespace
}  // namespace pnet
