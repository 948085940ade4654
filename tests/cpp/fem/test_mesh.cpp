// FEM meshes: validation and boundary extraction on hand-made meshes, gmsh's
// procedural shapes (areas, boundaries, determinism) and mesh files.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <fstream>

#include <Eigen/Geometry>  // cross()

#include "pnet/fem/gmsh_mesher.hpp"
#include "support/fem_systems.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

double total_volume(const Mesh<2>& m) {
    double v = 0.0;
    for (std::size_t e = 0; e < m.elements.size(); ++e) v += m.signed_volume(m.x, e);
    return v;
}

/// Boundary length and the signed area enclosed by the boundary edges (positive when they run
/// counter-clockwise around the body, i.e. outward normals).
std::pair<double, double> boundary_length_and_area(const Mesh<2>& m) {
    double length = 0.0, area = 0.0;
    for (const auto& f : m.boundary) {
        const Vec<2>& a = m.x[f[0]];
        const Vec<2>& b = m.x[f[1]];
        length += (b - a).norm();
        area += 0.5 * (a[0] * b[1] - b[0] * a[1]);
    }
    return {length, area};
}

TEST(Mesh, FinalizeOrientsElementsAndFindsTheBoundary) {
    // A unit square of two triangles, one given clockwise.
    Mesh<2> m;
    m.x = {Vec<2>(0, 0), Vec<2>(1, 0), Vec<2>(1, 1), Vec<2>(0, 1)};
    m.elements = {{0, 1, 2}, {0, 3, 2}};
    m.finalize("square");
    for (std::size_t e = 0; e < m.elements.size(); ++e) EXPECT_GT(m.signed_volume(m.x, e), 0.0);
    EXPECT_DOUBLE_EQ(total_volume(m), 1.0);
    ASSERT_EQ(m.boundary.size(), 4u) << "the diagonal is interior";
    const auto [length, area] = boundary_length_and_area(m);
    EXPECT_DOUBLE_EQ(length, 4.0);
    EXPECT_DOUBLE_EQ(area, 1.0) << "boundary edges run counter-clockwise (outward normals)";
}

TEST(Mesh, TetrahedronBoundaryFacesPointOutward) {
    Mesh<3> m;
    m.x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0, 1, 0), Vec<3>(0, 0, 1)};
    m.elements = {{0, 2, 1, 3}};  // negatively oriented: fixed by finalize
    m.finalize("tet");
    EXPECT_NEAR(m.signed_volume(m.x, 0), 1.0 / 6.0, 1e-15);
    ASSERT_EQ(m.boundary.size(), 4u);
    const Vec<3> centre(0.25, 0.25, 0.25);
    for (const auto& f : m.boundary) {
        const Vec<3> n = (m.x[f[1]] - m.x[f[0]]).cross(m.x[f[2]] - m.x[f[0]]);
        EXPECT_GT(n.dot(m.x[f[0]] - centre), 0.0) << "outward";
    }
}

TEST(Mesh, BadMeshesAreRefusedNamingTheElementOrNode) {
    auto message = [](Mesh<2> m) {
        try {
            m.finalize("m.msh");
        } catch (const MeshError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    Mesh<2> ok;
    ok.x = {Vec<2>(0, 0), Vec<2>(1, 0), Vec<2>(0, 1)};
    ok.elements = {{0, 1, 2}};
    EXPECT_EQ(message(ok), "accepted");
    Mesh<2> bad = ok;
    bad.elements = {{0, 1, 3}};
    EXPECT_EQ(message(bad), "m.msh: element 0 refers to node 3, but there are 3 nodes");
    bad.elements = {{0, 1, 1}};
    EXPECT_EQ(message(bad), "m.msh: element 0 uses node 1 twice");
    bad = ok;
    bad.x[2] = Vec<2>(2, 0);  // collinear
    EXPECT_NE(message(bad).find("m.msh: element 0 is degenerate"), std::string::npos);
    bad = ok;
    bad.x.push_back(Vec<2>(5, 5));
    EXPECT_EQ(message(bad), "m.msh: node 3 belongs to no element");
    bad = ok;
    bad.elements.clear();
    EXPECT_EQ(message(bad), "m.msh: the mesh has no elements");
}

TEST(GmshMesher, FrameHasTheRightAreaBoundaryAndSize) {
    const Shape2d frame = test::frame_shape(Vec<2>(0.0, 0.0), Vec<2>(0.10, 0.18), 0.012, 0.003);
    const Mesh<2> m = mesh_shape(frame, "metal frame");
    const double area = 0.10 * 0.18 - (0.10 - 0.024) * (0.18 - 0.024);
    EXPECT_NEAR(total_volume(m), area, 1e-12);
    const auto [length, enclosed] = boundary_length_and_area(m);
    EXPECT_NEAR(length, 2 * (0.10 + 0.18) + 2 * (0.076 + 0.156), 1e-12) << "outer and inner boundary";
    EXPECT_NEAR(enclosed, area, 1e-12) << "outward: the hole's edges run clockwise";
    double edge_sum = 0.0;
    int edges = 0;
    for (const auto& el : m.elements)
        for (int a = 0; a < 3; ++a, ++edges) edge_sum += (m.x[el[a]] - m.x[el[(a + 1) % 3]]).norm();
    EXPECT_NEAR(edge_sum / edges, 0.003, 0.001) << "elements of about the requested size";
    // gmsh runs with one thread but leaves the caller's OpenMP thread count alone.
    const int threads = omp_get_max_threads();
    omp_set_num_threads(2);
    mesh_shape(frame, "metal frame");
    EXPECT_EQ(omp_get_max_threads(), 2);
    omp_set_num_threads(threads);
    // Deterministic: the same call gives the same mesh.
    const Mesh<2> again = mesh_shape(frame, "metal frame");
    ASSERT_EQ(again.x.size(), m.x.size());
    ASSERT_EQ(again.elements.size(), m.elements.size());
    for (std::size_t i = 0; i < m.x.size(); ++i) EXPECT_EQ(again.x[i], m.x[i]);
}

TEST(GmshMesher, DiskAndBadShapes) {
    Shape2d disk;
    disk.kind = Shape2d::Kind::Disk;
    disk.center = Vec<2>(0.5, 0.3);
    disk.radius = 0.05;
    disk.element_size = 0.01;
    const Mesh<2> m = mesh_shape(disk, "disk");
    EXPECT_NEAR(total_volume(m), M_PI * 0.05 * 0.05, 0.02 * M_PI * 0.05 * 0.05) << "polygonal approximation";
    auto message = [](const Shape2d& s) {
        try {
            mesh_shape(s, "scene.json: objects[0]");
        } catch (const MeshError& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    Shape2d bad = disk;
    bad.element_size = 0.0;
    EXPECT_NE(message(bad).find("scene.json: objects[0]: element_size must be > 0"), std::string::npos);
    const Shape2d frame = test::frame_shape(Vec<2>::Zero(), Vec<2>(0.1, 0.1), 0.06, 0.01);
    EXPECT_NE(message(frame).find("the frame's thickness must be > 0 and leave a hole"), std::string::npos);
}

TEST(GmshMesher, ReadsMeshFilesAndRefusesBadOnes) {
    test::TempDir dir;
    const std::string path = dir.file("square.msh");
    {
        std::ofstream out(path);
        out << "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n4\n1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n$EndNodes\n"
               "$Elements\n3\n1 1 2 0 1 1 2\n2 2 2 0 1 1 2 3\n3 2 2 0 1 1 3 4\n$EndElements\n";
    }
    const Mesh<2> m = read_mesh_file<2>(path);
    EXPECT_EQ(m.x.size(), 4u);
    EXPECT_EQ(m.elements.size(), 2u);
    EXPECT_DOUBLE_EQ(total_volume(m), 1.0);
    EXPECT_EQ(m.boundary.size(), 4u);
    try {
        read_mesh_file<3>(path);
        ADD_FAILURE() << "a triangle mesh read as tetrahedra";
    } catch (const MeshError& e) {
        EXPECT_EQ(std::string(e.what()), path + ": no tetrahedra in the mesh");
    }
    EXPECT_THROW(read_mesh_file<2>(dir.file("missing.msh")), MeshError);
    const std::string garbage = dir.file("garbage.msh");
    {
        std::ofstream out(garbage);
        out << "this is not a mesh\n";
    }
    EXPECT_THROW(read_mesh_file<2>(garbage), MeshError);
}

TEST(GmshMesher, AnElementAsLargeAsTheShapeUpToRoundOffIsAccepted) {
    // 0.1911 - 0.1811 is 0.00999999... in doubles: a 1 cm plate meshed with 1 cm triangles.
    const Mesh<2> mesh = mesh_shape(test::box_shape<2>(Vec<2>(0.42, 0.1811), Vec<2>(0.58, 0.1911), 0.01), "plate");
    EXPECT_GT(mesh.elements.size(), 0u);
}

}  // namespace
}  // namespace pnet
