#pragma once
// VTK XML unstructured grids (.vtu; ParaView, VisIt, meshio): a FEM mesh
// (triangles in 2D, tetrahedra in 3D) or a particle cloud, with named point
// and cell fields. ASCII, so that a file can be read and diffed as text; the
// doubles are written with 17 significant digits (a round trip is exact).
//
//     <VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
//       <UnstructuredGrid><Piece NumberOfPoints=n NumberOfCells=m>
//         <PointData> one DataArray per point field </PointData>
//         <CellData> one DataArray per cell field </CellData>
//         <Points> n x 3 (2D: z = 0) </Points>
//         <Cells> connectivity, offsets, types (5 triangle, 10 tetrahedron, 1 vertex) </Cells>
//       </Piece></UnstructuredGrid>
//     </VTKFile>
#include <string>
#include <vector>

namespace pnet {

struct VtuField {
    std::string name;
    int components = 1;          // 1: scalar; dim: a vector (written with 3 components, 2D padded with 0)
    std::vector<double> values;  // count x components
};

struct VtuMesh {
    int dim = 2;
    std::vector<double> position;  // n * dim, m
    /// dim + 1 node indices per cell (triangles, tetrahedra); empty: one vertex cell per point
    /// (particles).
    std::vector<int> cells;
    std::vector<VtuField> point_data, cell_data;
};

/// Writes m atomically. Throws std::invalid_argument "<path>: ..." for a dim other than 2 or 3,
/// sizes that disagree, a node index out of range or a field name that is empty or not plain
/// (letters, digits, '_' and '-'); std::runtime_error if the file cannot be written.
void write_vtu(const std::string& path, const VtuMesh& m);

}  // namespace pnet
