#pragma once
// A simplicial FEM mesh (docs/methods.md): linear triangles in 2D, linear
// tetrahedra in 3D, with rest positions, and its boundary facets (edges in 2D,
// triangles in 3D), which contact acts on (contact/).
//
// Elements are oriented positively: det [x1 - x0, ..., xd - x0] > 0. Boundary
// facets are oriented so that their outward normal points out of the body
// (2D: the body lies to the left of the edge a -> b).
#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/math/types.hpp"

namespace pnet {

/// A mesh that cannot be used: bad indices, a degenerate element, an unused
/// node. The message names the file or shape ("context"), the element or node
/// and the problem.
class MeshError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

template <int dim>
struct Mesh {
    static constexpr int kElementNodes = dim + 1;
    using Element = std::array<int, dim + 1>;
    using Facet = std::array<int, dim>;

    std::vector<Vec<dim>> x;          // rest positions, m
    std::vector<Element> elements;    // node indices
    std::vector<Facet> boundary;      // boundary facets, outward oriented (finalize())

    std::size_t nodes() const { return x.size(); }

    /// Checks the mesh and makes it usable: every index in range, no repeated
    /// node within an element, every element of volume above 1e-12 h^d (h the
    /// mean edge length) turned positive by swapping two of its nodes, every
    /// node used by some element; then extracts the boundary facets (those of
    /// exactly one element) in a fixed order. Throws MeshError naming `context`.
    void finalize(const std::string& context);

    /// Adds the nodes and elements of `other` (node indices shifted); call
    /// finalize() afterwards. Returns the index of other's first node here.
    int append(const Mesh& other);

    /// Signed volume of element e at positions `positions` (m^d).
    double signed_volume(const std::vector<Vec<dim>>& positions, std::size_t e) const;

    /// Smallest and largest corner of the rest positions.
    std::pair<Vec<dim>, Vec<dim>> bounding_box() const;
};

}  // namespace pnet
