#include "pnet/fem/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <map>

namespace pnet {

template <int dim>
double Mesh<dim>::signed_volume(const std::vector<Vec<dim>>& positions, std::size_t e) const {
    Mat<dim> D;
    for (int a = 0; a < dim; ++a) D.col(a) = positions[elements[e][a + 1]] - positions[elements[e][0]];
    return D.determinant() / (dim == 2 ? 2.0 : 6.0);
}

template <int dim>
int Mesh<dim>::append(const Mesh& other) {
    const int offset = static_cast<int>(x.size());
    x.insert(x.end(), other.x.begin(), other.x.end());
    for (Element el : other.elements) {
        for (int& a : el) a += offset;
        elements.push_back(el);
    }
    return offset;
}

template <int dim>
std::pair<Vec<dim>, Vec<dim>> Mesh<dim>::bounding_box() const {
    Vec<dim> lo = Vec<dim>::Constant(1e300), hi = Vec<dim>::Constant(-1e300);
    for (const Vec<dim>& p : x) {
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
    }
    return {lo, hi};
}

template <int dim>
void Mesh<dim>::finalize(const std::string& context) {
    auto fail = [&](const std::string& what) { throw MeshError(context + ": " + what); };
    const int n = static_cast<int>(x.size());
    if (elements.empty()) fail("the mesh has no elements");
    for (std::size_t i = 0; i < x.size(); ++i)
        if (!x[i].allFinite()) fail("node " + std::to_string(i) + " has a non-finite position");
    double edge_sum = 0.0;
    for (std::size_t e = 0; e < elements.size(); ++e) {
        const Element& el = elements[e];
        for (int a = 0; a < kElementNodes; ++a) {
            if (el[a] < 0 || el[a] >= n)
                fail("element " + std::to_string(e) + " refers to node " + std::to_string(el[a]) + ", but there are " +
                     std::to_string(n) + " nodes");
            for (int b = 0; b < a; ++b)
                if (el[a] == el[b])
                    fail("element " + std::to_string(e) + " uses node " + std::to_string(el[a]) + " twice");
        }
        for (int a = 0; a < kElementNodes; ++a)
            for (int b = 0; b < a; ++b) edge_sum += (x[el[a]] - x[el[b]]).norm();
    }
    const double h = edge_sum / (elements.size() * (kElementNodes * dim / 2.0));
    const double min_volume = 1e-12 * std::pow(h, dim);
    for (std::size_t e = 0; e < elements.size(); ++e) {
        const double v = signed_volume(x, e);
        if (!(std::abs(v) > min_volume))
            fail("element " + std::to_string(e) + " is degenerate (volume " + std::to_string(v) + ")");
        if (v < 0.0) std::swap(elements[e][1], elements[e][2]);
    }
    std::vector<char> used(x.size(), 0);
    for (const Element& el : elements)
        for (int a : el) used[a] = 1;
    for (std::size_t i = 0; i < used.size(); ++i)
        if (!used[i]) fail("node " + std::to_string(i) + " belongs to no element");

    // Boundary: the facets (opposite each node of an element, oriented with the
    // element) that belong to exactly one element.
    std::map<std::array<int, dim>, std::pair<int, Facet>> count;  // sorted facet -> (uses, oriented facet)
    for (const Element& el : elements)
        for (int skip = 0; skip < kElementNodes; ++skip) {
            Facet f;
            if constexpr (dim == 2) {
                // Edge opposite node `skip`, counter-clockwise around the element.
                f = {el[(skip + 1) % 3], el[(skip + 2) % 3]};
            } else {
                // Face opposite node `skip`, its normal pointing away from node `skip`.
                static constexpr int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
                f = {el[faces[skip][0]], el[faces[skip][1]], el[faces[skip][2]]};
            }
            Facet key = f;
            std::sort(key.begin(), key.end());
            auto [it, inserted] = count.try_emplace(key, 0, f);
            ++it->second.first;
            if (it->second.first > 2)
                fail("a facet is shared by more than two elements (nodes " + std::to_string(key[0]) + ", " +
                     std::to_string(key[1]) + (dim == 3 ? ", " + std::to_string(key[dim - 1]) : "") + ")");
        }
    boundary.clear();
    for (const auto& [key, value] : count)
        if (value.first == 1) boundary.push_back(value.second);
}

template struct Mesh<2>;
template struct Mesh<3>;

}  // namespace pnet
